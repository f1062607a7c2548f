"""Equal-time gains of the projective-sampling guides, from the bench reports of the paper's test
scene: `.venv/bin/python tests/bench/projective_summary.py [--budget 1024] [--dir docs/reports/projective] [--kept K]`.

Reads the tables that `python3 -m limn bench scenes/projective/<scene>.json ...` wrote and prints,
per scene and as a geometric mean, the equal-time error ratios the paper reports (Figure 1:
projection over the path-space baseline grid, 8.1x; the octree over the projective grid, a
further 2.7x). Each error is scaled to a common time by error ~ time^-1/2 (independent samples;
the guide's set-up is part of the time) before the ratio is taken. `--kept K` counts each guide's
set-up once per K calls, as an optimisation with `guide_refresh=K` pays it (derived from the same
rows, not measured: a guide kept while the parameters move is also less well matched)."""
from __future__ import annotations

import argparse
import math
import os

SCENES = ["sphere", "torus", "cube_hole", "bunny"]
# (label, slower method, faster method): ratio = error of the first / error of the second at equal time.
STEPS = [("projective grid over the baseline grid 1x", "grid", "projective_grid"),
         ("projective grid over the baseline grid 10x", "grid10x", "projective_grid"),
         ("octree, projections only, over the projective grid", "projective_grid", "octree_untrained"),
         ("octree with the training round over the projective grid", "projective_grid", "octree_unrefined"),
         ("octree (training, refinement: the default) over the projective grid", "projective_grid", "octree"),
         ("octree: refinement rounds over none", "octree_unrefined", "octree"),
         ("octree (the default) over the baseline grid 1x", "grid", "octree"),
         # The paper's grid (one grid, no direction histogram): its two steps, as the paper took them.
         ("the paper's projective grid over the baseline grid 1x", "grid", "paper_projective_grid"),
         ("octree (the default) over the paper's projective grid", "paper_projective_grid", "octree"),
         # Stratified boundary points (the default) against independent ones (`method:independent`).
         ("baseline grid: stratified over independent points", "grid:independent", "grid"),
         ("projective grid: stratified over independent points", "projective_grid:independent", "projective_grid"),
         ("octree: stratified over independent points", "octree:independent", "octree"),
         ("projective grid over the baseline grid, both with independent points", "grid:independent", "projective_grid:independent"),
         ("octree over the projective grid, both with independent points", "projective_grid:independent", "octree:independent"),
         ("octree over the baseline grid, both with independent points", "grid:independent", "octree:independent")]


def read_rows(path: str, column: int, kept: int = 1) -> dict[tuple[str, int], tuple[float, float]]:
    """{(method, budget): (time, error)} from a bench report's table (column 4: relative RMSE,
    the root mean square over the runs; 6: relative MAE, the mean over the runs; 7: run-to-run
    noise, the estimator's standard deviation). The time counts the guide's set-up (column 3) once
    per `kept` calls."""
    rows = {}
    with open(path) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) >= 7 and cells[1].isdigit() and column < len(cells) and not cells[column].startswith("n/a"):
                setup = float(cells[3])
                rows[(cells[0], int(cells[1]))] = (float(cells[2]) - setup + setup / kept, float(cells[column]))
    return rows


def equal_time_ratio(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Error of a over error of b once both are scaled to b's time (error ~ time^-1/2)."""
    return a[1] * math.sqrt(a[0] / b[0]) / b[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", type=int, default=1024, help="the rows (samples per pixel) to compare")
    ap.add_argument("--dir", default=os.path.join("docs", "reports", "projective"))
    ap.add_argument("--kept", type=int, default=1, help="count each guide's set-up once per K calls (guide_refresh=K)")
    args = ap.parse_args()
    for column, measure in ((4, "RMSE (L2; single outlier runs dominate it)"), (6, "MAE (L1)"),
                            (7, "run-to-run noise (the RMSE against a reference without error: the estimators are unbiased)")):
        tables = {s: read_rows(os.path.join(args.dir, s + ".md"), column, args.kept) for s in SCENES if os.path.exists(os.path.join(args.dir, s + ".md"))}
        kept = f", each guide's set-up counted once per {args.kept} calls" if args.kept > 1 else ""
        print(f"Equal-time gains in relative {measure} at the {args.budget}-spp rows (error ratio after scaling by time^-1/2{kept}):\n")
        print("| step | " + " | ".join(tables) + " | geometric mean |")
        print("|---|" + "---|" * (len(tables) + 1))
        print_steps(tables, args.budget)
        print()


def print_steps(tables: dict, budget: int) -> None:
    for label, slow, fast in STEPS:
        ratios = []
        for rows in tables.values():
            a, b = rows.get((slow, budget)), rows.get((fast, budget))
            ratios.append(equal_time_ratio(a, b) if a and b else float("nan"))
        valid = [r for r in ratios if r == r]
        if not valid:
            continue  # neither method in these tables
        gm = math.exp(sum(math.log(r) for r in valid) / len(valid)) if valid else float("nan")
        print(f"| {label} | " + " | ".join(f"{r:.1f}x" if r == r else "n/a" for r in ratios) + (f" | {gm:.1f}x |" if gm == gm else " | n/a |"))


if __name__ == "__main__":
    main()
