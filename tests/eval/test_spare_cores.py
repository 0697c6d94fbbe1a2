"""``Evaluator(spare_cores=...)``: a grasp that starts while a core sits idle steps its six
directions on 2 threads. The reference is the same evaluator on one thread: every number of the
result must be equal (MuJoCo is deterministic, the lockstep schedule is the same)."""

from datagen.eval import EvalConfig, Evaluator
from tests.eval.grasps import box_grasp


def test_an_idle_core_changes_nothing_but_the_threads(shadow, box_dir):
    asked = []

    def idle() -> int:
        asked.append(1)
        return 1

    with Evaluator(shadow, EvalConfig()) as one, Evaluator(shadow, EvalConfig(), spare_cores=idle) as two, \
            Evaluator(shadow, EvalConfig(), spare_cores=lambda: 0) as busy:
        pieces, poses = box_grasp(one, (0.03, 0.015, 0.03), 0.0, box_dir)
        a, b, c = one.evaluate(pieces, poses), two.evaluate(pieces, poses), busy.evaluate(pieces, poses)
        assert two._spare_pool is not None and busy._spare_pool is None and asked
    assert a.reason == "ok" and a == b == c
