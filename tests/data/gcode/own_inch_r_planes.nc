%
(stiffmap test program: inch, R-format arcs written without spaces, in every plane)
n10g20g90g94g17
n20g0x0y0z0.2
n30g1z0f10.
n40g2x1.y1.r1.f20.
n50g3x2.y0.r1.
n60g1x2.y-0.5
n70g18g2x2.5z0.r0.25
n80g19g3y0.z0.r0.25
n90g17g1x0.y0.
n100g0z0.2
n110m30
%
