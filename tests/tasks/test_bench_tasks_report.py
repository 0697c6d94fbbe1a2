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
