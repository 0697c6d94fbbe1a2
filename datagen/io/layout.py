"""The on-disk layout of a job directory, as named constants (written by ``workers``, read here).

    job.json                     the job's config, its hash, code and package versions
    manifest.jsonl               the manifest slice of the job
    shards/part-NNNNN.parquet    grasp rows of shard N (schema ``evaluated``)
    observations/part-NNNNN.parquet  object observations of shard N's objects, one row per object and
                                 scale (schema ``observations``: point clouds, camera views)
    failures/part-NNNNN.parquet  failed objects of shard N (schema ``failures``)
    failures.parquet             all failures
    objects/<entry>/             processed objects; rows' ``object_path`` is relative to the job dir
    failures/manifest.parquet    objects of the source that the manifest cannot hold (stage ``manifest``)
    ledger/part-NNNNN.json       present once shard N is finished (its counts, timings and files)
    ledger/manifest.json         manifest.jsonl's size, line count and sha256, written with it
    progress/part-NNNNN.json     a running shard's progress (polled by the driver)
    .lock                        flock held by the running driver
    hands/<name>.yaml            the job's hand, pinned (`datagen.hands.pin.HANDS_DIR`): rows' ``hand``
                                 names it; readers load it from here (``load_hand(name, base=job)``)
"""

JOB_JSON = "job.json"
MANIFEST = "manifest.jsonl"
SHARDS_DIR = "shards"
OBSERVATIONS_DIR = "observations"
FAILURES_DIR = "failures"
FAILURES = "failures.parquet"
OBJECTS_DIR = "objects"
LEDGER_DIR = "ledger"
MANIFEST_RECORD = "manifest.json"  # in LEDGER_DIR
LOCK = ".lock"
PROGRESS_DIR = "progress"
MANIFEST_FAILURES = "manifest.parquet"
SHARD_NAME = "part-{index:05d}"
