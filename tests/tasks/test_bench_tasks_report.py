"""`make bench-tasks` rewrites tasks.md from its records: sections whose records are gone stay."""

from benchmarks.bench_tasks import write_report


def test_rewrite_keeps_sections_without_records_and_the_notes(tmp_path):
    out = tmp_path / "tasks.md"
    out.write_text("# Title\n\nMachine: old\n\n# Results at code version aaa\n\nold A\n\n"
                   "# Results at code version bbb\n\nold B\n\n## Notes (hand-written, kept)\n\n- a note\n\n"
                   "tasks-generic: full=1 baseline=0\n")
    rendered = "# Title\n\nMachine: new\n\n# Results at code version bbb\n\nnew B\n\n# Results at code version ccc\n\nnew C\n"
    write_report(out, rendered, "tasks-generic: full=2 baseline=1")
    text = out.read_text()
    assert "Machine: new" in text and "Machine: old" not in text
    assert "old A" in text and "old B" not in text  # a version with records is rendered afresh
    order = [text.index(s) for s in ("# Results at code version aaa", "# Results at code version bbb",
                                      "# Results at code version ccc", "## Notes", "- a note")]
    assert order == sorted(order)
    assert text.count("# Results at code version") == 3
    assert text.rstrip("\n").splitlines()[-1] == "tasks-generic: full=2 baseline=1"
    assert "full=1 baseline=0" not in text


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
