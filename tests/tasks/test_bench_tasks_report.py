"""`make bench-tasks` rewrites tasks.md from its records: the latest complete version per hand
and initialisation, newest first; the hand-written notes stay."""

from benchmarks.bench_tasks import TASKS, latest_complete, write_report


def test_rewrite_replaces_the_results_and_keeps_the_notes(tmp_path):
    out = tmp_path / "tasks.md"
    out.write_text("# Title\n\nMachine: old\n\n# Results at code version aaa\n\nold A\n\n"
                   "## Notes (hand-written, kept)\n\n- a note\n\ntasks-generic: full=1 baseline=0\n")
    rendered = "# Title\n\nMachine: new\n\n# Results at code version ccc\n\nnew C\n"
    write_report(out, rendered, "tasks-generic: full=2 baseline=1")
    text = out.read_text()
    assert "Machine: new" in text and "old A" not in text and "new C" in text  # history is git's
    assert text.index("new C") < text.index("## Notes") < text.index("- a note")
    assert text.rstrip("\n").splitlines()[-1] == "tasks-generic: full=2 baseline=1"


def test_the_latest_version_covering_every_task_is_shown():
    def rec(v, task, hand="shadow", init="task", variant="full"):
        return {"code_version": v, "task": task, "hand": hand, "init": init, "variant": variant}
    recs = [rec("a", t) for t in TASKS] + [rec("b", TASKS[0])] + [rec("b", t, init="generic") for t in TASKS[:2]]
    assert latest_complete(recs, ["a", "b"]) == {("shadow", "task"): "a", ("shadow", "generic"): "b"}
    recs += [rec("c", t) for t in TASKS]
    assert latest_complete(recs, ["a", "b", "c"])[("shadow", "task")] == "c"


def test_rewrite_without_generic_records_keeps_the_headline(tmp_path):
    out = tmp_path / "tasks.md"
    out.write_text("# Title\n\n## Notes (hand-written, kept)\n\n- a note\n\n"
                   "tasks-generic: full=68.3 baseline=46.8 (ten tasks, shadow, N=100 poses per task, code abc)\n")
    write_report(out, "# Title\n", "tasks-generic: full=- baseline=- (no complete generic-initialisation run of shadow yet)")
    assert out.read_text().rstrip("\n").splitlines()[-1].startswith("tasks-generic: full=68.3 baseline=46.8")


def test_held_comparison_against_an_enumerated_permutation_test():
    """One-sided p of "full holds more": the share of the 70 ways to split the 8 poses 4 / 4
    whose full-side rank sum is at least the observed one (no ties: the exact Mann-Whitney)."""
    import itertools

    import pytest

    from benchmarks.bench_tasks import held_comparison

    full, base = [2.0, 5.66, 8.0, 32.0], [0.25, 1.0, 4.0, 4.76]
    values = full + base
    ranks = {v: r for r, v in enumerate(sorted(values), 1)}
    observed = sum(ranks[v] for v in full)
    splits = list(itertools.combinations(values, 4))
    p_ref = sum(sum(ranks[v] for v in s) >= observed for s in splits) / len(splits)
    cell, higher, p = held_comparison({"held_multiple": full}, {"held_multiple": base})
    assert higher and cell.startswith("higher") and p == pytest.approx(p_ref)
    assert held_comparison({"held_multiple": base}, {"held_multiple": full})[1] is False
    tie = held_comparison({"held_multiple": [4.0] * 5}, {"held_multiple": [4.0] * 5})
    assert tie == ("tie (p 1)", False, 1.0)
    assert held_comparison({"held_multiple": full}, None) is None
