"""Look at grasps in 3D in a web page: ``datagen view JOB|SHARD|FILE`` and ``--export DIR``.

    from datagen.view import open_source
    source = open_source("jobs/default")           # rows, where object_path points, eval config
    from datagen.view.app import Browser           # needs the `view` extra (viser)
    print(Browser(source, port=8080).url)

The hand and the object are the evaluation's own MuJoCo scene (`posing`): the page shows what
was simulated. `source`, `posing` and `panel` need no viser; `app`, `draw` and `export` do.
"""

from .panel import row_markdown, verdict_line
from .posing import STATES, SceneCache
from .source import GraspSource, ViewError, find_column, open_source

__all__ = ["GraspSource", "STATES", "SceneCache", "ViewError", "find_column", "open_source", "row_markdown",
           "verdict_line"]
