"""``stiffmap demo``: what ``make demo`` runs.

Until the virtual test-bed and campaigns land, the demo identifies a known
stiffness from the reference study's nine load cases with simulated
displacement noise, and prints the three estimators beside the truth.
"""

from __future__ import annotations

import typer
from rich.table import Table

from .common import fmt, out


def demo(
    seed: int = typer.Option(1, "--seed", help="Seed of the simulated noise."),
    repeats: int = typer.Option(10, "--repeats", min=1, help="Repeated measurements per load case."),
    noise_mm: float = typer.Option(0.005, "--noise-mm", min=0.0, help="Displacement noise, 1 sigma, mm."),
) -> None:
    """Identify a known stiffness from simulated measurements of the reference load design."""
    import numpy as np

    from ..identify import METHODS, identify_stiffness
    from ..loads import forces_matrix, paper9

    rng = np.random.default_rng(seed)
    # An anisotropic, symmetric, positive-definite stiffness of the order the
    # reference study measured (a few N/mm), in the base frame.
    A = rng.normal(size=(3, 3))
    Q, _ = np.linalg.qr(A)
    K_true = Q @ np.diag([1.5, 4.0, 9.0]) @ Q.T
    F1 = forces_matrix(paper9())
    F = np.tile(F1, repeats)
    D = np.linalg.solve(K_true, F) + rng.normal(scale=noise_mm, size=F.shape)
    out.print(f"true K (N/mm), nine load cases x {repeats} repeats, noise {noise_mm} mm (1 sigma):")
    t = Table("method", "K (rows)", "|K - K_true| / |K_true| (Frobenius)", "flags")
    t.add_row("truth", " | ".join(", ".join(fmt(x, 4) for x in row) for row in K_true), "", "")
    worst = 0.0
    for meth in METHODS:
        fit = identify_stiffness(F, D, method=meth)
        err = float(np.linalg.norm(fit.K - K_true) / np.linalg.norm(K_true))
        if meth == "compliance":
            worst = err
        t.add_row(
            meth,
            " | ".join(", ".join(fmt(x, 4) for x in row) for row in fit.K),
            f"{100 * err:.3f} %",
            "; ".join(fit.flags) or "none",
        )
    out.print(t)
    out.print(f"worst relative K error: {100 * worst:.3f} %")


def register(app: typer.Typer) -> None:
    app.command("demo")(demo)
