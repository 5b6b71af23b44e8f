"""The README's picture: λ(t) and K(t) of LNVA and JVJA on the paper's Fig. 2 case.

``python scripts/readme_figure.py [OUT_STEM]`` (default ``docs/img/fig2_lnva_jvja``) writes
OUT_STEM.png with the toolkit's own plotting and prints each algorithm's mean jump.
"""

import sys

import fault_tolerance as ft
from fault_tolerance.figures.runs import plot_comparison, save_figure
from fault_tolerance.paper.cases import CASES


def main(stem: str = "docs/img/fig2_lnva_jvja") -> dict:
    case = CASES["fig2"]
    arm = ft.load_arm(case.robot)
    path = case.path()
    q0 = ft.initial_posture(arm, path.x0, list(case.lockable)).q
    runs = {
        a: ft.simulate(arm, path, a, q0=q0, lockable=list(case.lockable)) for a in ("lnva", "jvja")
    }
    fig = plot_comparison(runs, title="planar 3R, Fig. 2 circle, every joint lockable")
    save_figure(fig, stem, formats=("png",))
    means = {a: r.summary()["jvj_mean"] for a, r in runs.items()}
    for a, m in means.items():
        print(f"{a}: mean jump {m:.4f} (rad/s)^2")
    print(f"wrote {stem}.png")
    return means


if __name__ == "__main__":
    main(*sys.argv[1:2])
