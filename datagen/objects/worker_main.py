"""Entry point of an `isolated_worker.IsolatedWorker`: ``python -m datagen.objects.worker_main
REQUESTS_FD RESULTS_FD``. Its Ctrl-C policy ("die") is set before anything heavy is imported."""

if __name__ == "__main__":
    import sys

    from datagen._interrupt import on_sigint

    on_sigint("die")
    from multiprocessing.connection import Connection

    from datagen.objects.isolated_worker import serve

    serve(Connection(int(sys.argv[1]), writable=False), Connection(int(sys.argv[2]), readable=False))
