"""Parallel robots with flexible links in their legs: link and leg parameters fitted together.

Two robots described by their legs with ``[[legs.links]]`` (docs/models.md, "Flexible links in
legs"), their measurements computed by the model from the true parameters plus Gaussian noise,
fitted from a start 30-50 % off, over many seeds:

- **delta_links** (shipped: the Delta with aluminium-tube upper arms, 30 x 2 mm, 300 mm): the
  reference study's 48 positions (paper48) and nine load cases (0.5, 0.2, 0.1 kg along +y, -x,
  -z), each static error read along x, y and z with 1 um noise; k_theta and E_arm fitted by
  ``fit_static_errors`` (G_arm never matters: ball-jointed elbows; not fitted).
- **3-RPS with tube legs** (robots/3rps.toml, its bending springs replaced by a steel tube of
  20 x 2 mm, 270 mm, in series with each actuator: a beam link after the stroke): six heights
  (level platform) and the nine load cases hung 100 mm below the platform's centre (moments
  too), 6-DOF deflections with 1 um and 5 urad noise per axis; k_leg1..3 and E_tube fitted by
  ``fit_deflections6``.

Per parameter: the largest error, the reported standard error, the scatter of the estimates
about the truth and their ratio (1 when the standard errors are right), the share within two
standard errors, and the RMS of the z-scores (estimate - truth) / std.

Run:  .venv/bin/python benchmarks/bench_legs_links.py [--seeds 40]
Saves benchmarks/results/legs_links.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from importlib.resources import files
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

sys.path.insert(0, str(HERE))
from _table import save  # noqa: E402

from stiffmap.models.fit import fit_deflections6, fit_static_errors  # noqa: E402
from stiffmap.models.legs import LegRobot  # noqa: E402
from stiffmap.models.legs6 import rps3_toml  # noqa: E402
from stiffmap.models.presets import paper48  # noqa: E402
from stiffmap.units import G_STANDARD  # noqa: E402

ROBOTS = files("stiffmap.models") / "robots"
LOADS = [m * G_STANDARD * d for m in (0.5, 0.2, 0.1) for d in (np.eye(3)[1], -np.eye(3)[0], -np.eye(3)[2])]
TUBE = """
[[legs.links]]
after = "stroke"
name = "tube"
[legs.links.beam]
length_mm = 270.0
E_MPa = 210000.0
G_MPa = 81000.0
area_mm2 = 113.1
Iy_mm4 = 4637.0
Iz_mm4 = 4637.0
J_mm4 = 9274.0
axis = "z"
"""


def delta_case():
    """(truth, start, fit(model, data noisy) -> ModelFit, clean data, noise, names, rigid-link share)."""
    truth = LegRobot.from_toml(ROBOTS / "delta_links.toml")
    P = np.repeat(paper48(), len(LOADS) * 3, axis=0)
    F = np.tile(np.repeat(np.array(LOADS), 3, axis=0), (48, 1))
    U = np.tile(np.eye(3), (48 * len(LOADS), 1))
    clean = np.einsum("ij,ij->i", truth.static_error(P, F), U)
    rigid = np.einsum("ij,ij->i", truth.with_params(E_arm=1e7).static_error(P, F), U)
    std = np.full(clean.shape, 1e-3)
    names = ("k_theta", "E_arm")
    start = truth.with_params(k_theta=1.5 * truth.params()["k_theta"], E_arm=1e5)

    def fit(y):
        return fit_static_errors(start, P, F, U, y, params=names, std=std, absolute_sigma=True)

    share = np.linalg.norm(clean - rigid) / np.linalg.norm(clean)
    return truth, fit, clean, std, names, share, f"{len(clean)} static-error readings (48 positions)"


def rps_case():
    text = rps3_toml({"k_bend": math.inf})
    head, *legs = text.split("\n[[legs]]\n")
    text = head + "".join(f"\n[[legs]]\n{lg.rstrip()}\n{TUBE}" for lg in legs)
    truth = LegRobot.from_toml_text(text, source="3rps_tubes.toml").with_params(
        k_leg1=400.0, k_leg2=550.0, k_leg3=700.0
    )
    P = np.zeros((6, 6))
    P[:, 2] = np.linspace(220.0, 290.0, 6)
    P = np.repeat(P, len(LOADS), axis=0)
    lever = np.array([0.0, 0.0, -100.0])
    W = np.tile([np.concatenate([f, np.cross(lever, f)]) for f in LOADS], (6, 1))
    clean = truth.static_error6(P, W)
    rigid = truth.with_params(E_tube=1e7).static_error6(P, W)
    std = np.tile([1e-3, 1e-3, 1e-3, 5e-6, 5e-6, 5e-6], (len(W), 1))
    names = ("k_leg1", "k_leg2", "k_leg3", "E_tube")
    start = truth.with_params(k_leg1=600.0, k_leg2=600.0, k_leg3=600.0, E_tube=1.4e5)

    def fit(D):
        return fit_deflections6(start, P, W, D, params=names, std=std, absolute_sigma=True)

    share = np.linalg.norm((clean - rigid)[:, :3]) / np.linalg.norm(clean[:, :3])
    return truth, fit, clean, std, names, share, f"{len(W)} 6-DOF deflections (6 heights)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=40)
    args = ap.parse_args()
    rows, notes = [], []
    for label, case in (("delta_links", delta_case), ("3-RPS, tube legs", rps_case)):
        truth, fit, clean, std, names, share, what = case()
        true = np.array([truth.params()[n] for n in names])
        est, sd = [], []
        t0 = time.perf_counter()
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            f = fit(clean + std * rng.normal(size=clean.shape))
            est.append(f.estimate)
            sd.append(f.std)
        dt = (time.perf_counter() - t0) / args.seeds
        E, S = np.array(est), np.array(sd)
        z = (E - true) / S
        scatter = np.sqrt(np.mean((E - true) ** 2, axis=0))
        reported = np.sqrt(np.mean(S**2, axis=0))
        for j, n in enumerate(names):
            rows.append(
                [
                    label,
                    n,
                    f"{true[j]:.4g}",
                    f"{np.mean(E[:, j]):.5g}",
                    f"{100 * np.max(np.abs(E[:, j] / true[j] - 1)):.3f}",
                    f"{100 * reported[j] / true[j]:.3f}",
                    f"{100 * scatter[j] / true[j]:.3f}",
                    f"{scatter[j] / reported[j]:.2f}",
                    f"{100 * np.mean(np.abs(z[:, j]) < 2):.0f}",
                    f"{float(np.sqrt(np.mean(z[:, j] ** 2))):.2f}",
                ]
            )
        notes.append(
            f"{label}: {what}; the links make {100 * share:.1f} % of the deflections (norm of the "
            f"difference with rigid links, translations); {1e3 * dt:.0f} ms per fit."
        )
    intro = (
        f"Seeds 0..{args.seeds - 1}. " + " ".join(notes) + " Stiffnesses in N*mm/rad (k_theta) or N/mm "
        "(k_leg), moduli in MPa; errors, standard errors and scatter in % of the truth; 'within 2 std': "
        "the share of seeds whose estimate lies within two reported standard errors (95 % when they are "
        "right); RMS z: of (estimate - truth) / std (1 when right)."
    )
    save(
        "legs_links",
        "Parallel robots with flexible links in their legs: link and leg parameters fitted together",
        [
            "robot",
            "parameter",
            "truth",
            "mean estimate",
            "max error %",
            "reported std %",
            "scatter %",
            "scatter / std",
            "within 2 std %",
            "RMS z",
        ],
        rows,
        intro,
    )


if __name__ == "__main__":
    main()
