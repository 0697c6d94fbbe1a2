"""The row's numbers on the page: verdict and reason, metrics with units, per-direction results."""

import math

from datagen.eval.config import DIRECTION_NAMES
from datagen.view import row_markdown, verdict_line


def test_verdict_reason_and_numbers(source):
    for i in range(len(source)):
        row = source.row(i)
        text = row_markdown(source, i)
        want = "Verdict: success" if row["success"] else f"Verdict: failure ({row['reason']})"
        assert verdict_line(source, i) == want
        assert f"**{want}**" in text
        assert f"| epsilon (MuJoCo contacts) | {row['epsilon']:.4g} |" in text or math.isnan(row["epsilon"])
        assert f"| penetration at the grasp | {1000 * row['penetration_m']:.2f} mm |" in text
        lines = [ln for ln in text.splitlines() if ln.startswith(tuple(f"| {d} |" for d in DIRECTION_NAMES))]
        assert len(lines) == 6
        for d, ok, moved in zip(DIRECTION_NAMES, row["dir_success"], row["dir_translation_m"]):
            held = {True: "yes", False: "no", None: "not run"}[ok]
            shown = "-" if moved is None or math.isnan(moved) else f"{1000 * moved:.2f} mm"
            assert f"| {d} | {held} | {shown} |" in text


def test_not_evaluated_table(source, job_dir, tmp_path):
    import pyarrow.parquet as pq

    from datagen.io import read_job
    from datagen.view import open_source

    t = read_job(job_dir).drop_columns(["success", "reason"])
    t = t.set_column(t.column_names.index("object_path"), "object_path",
                     [[str(source.object_dir(i)) for i in range(len(source))]])
    pq.write_table(t, tmp_path / "grasps.parquet")
    other = open_source(tmp_path / "grasps.parquet")
    assert verdict_line(other, 0) == "Verdict: not evaluated"
    assert set(other.verdicts()) == {"not evaluated"}
