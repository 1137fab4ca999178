"""sweep.md and sweep.json over training seeds: each configuration's mean, min and max of every metric over the
seeds whose point is done, in grid order; none without a seed axis of two or more values."""

from __future__ import annotations

from quadfdi.sweep_report import seed_means, sweep_markdown

GRID = [("train.hidden", ["40", "56"]), ("train.seed", ["0", "1", "2"])]
METRICS = ["history.cnode.val_macro_f1", "train.cnode.macro_f1"]


def _row(hidden: str, seed: str, val, test, status: str = "done") -> dict:
    return {"point": f"hidden-{hidden}_seed-{seed}", "values": {"train.hidden": hidden, "train.seed": seed},
            "status": status, "metrics": {METRICS[0]: val, METRICS[1]: test},
            "error": None if status == "done" else "boom"}


ROWS = [_row("40", "0", 0.30, 0.25), _row("40", "1", 0.34, 0.27), _row("40", "2", None, None, "failed"),
        _row("56", "0", 0.40, None), _row("56", "1", 0.36, None), _row("56", "2", 0.38, None)]


def test_each_configuration_is_summarised_over_the_seeds_done():
    means = seed_means(GRID, ROWS, METRICS)
    assert [e["values"] for e in means] == [{"train.hidden": "40"}, {"train.hidden": "56"}]
    first, second = means
    assert first["seeds_done"] == ["0", "1"] and first["seeds"] == 3
    assert abs(first["metrics"][METRICS[0]]["mean"] - 0.32) < 1e-12
    val = first["metrics"][METRICS[0]]
    assert (val["min"], val["max"], val["n"]) == (0.30, 0.34, 2)
    assert abs(second["metrics"][METRICS[0]]["mean"] - 0.38) < 1e-12 and second["metrics"][METRICS[1]] is None
    md = sweep_markdown(GRID, ROWS, METRICS, ("train",))
    assert "Per configuration over train.seed in {0, 1, 2}, in grid order:" in md
    assert "| 40 | 2 of 3 | 0.32 [0.3, 0.34] | 0.26 [0.25, 0.27] |" in md
    assert "| 56 | 3 of 3 | 0.38 [0.36, 0.4] | n/a |" in md


def test_no_summary_without_two_seeds():
    grid = [("train.hidden", ["40", "56"]), ("train.seed", ["0"])]
    rows = [r for r in ROWS if r["values"]["train.seed"] == "0"]
    assert seed_means(grid, rows, METRICS) == []
    assert "Per configuration" not in sweep_markdown(grid, rows, METRICS, ("train",))
    assert seed_means([("train.hidden", ["40", "56"])], rows, METRICS) == []
