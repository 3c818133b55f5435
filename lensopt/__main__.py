"""The ``lensopt`` command: ``python -m lensopt``, ``torchrun … -m lensopt`` and the console script
(``[project.scripts]`` → ``main``)."""


def main() -> None:
    """Install the process's signal handling (``lensopt.cli.signals``) before anything slow is imported, then
    run the command line."""
    from lensopt.cli import signals

    signals.install()
    from lensopt.cli.app import app

    app(prog_name="lensopt")


if __name__ == "__main__":  # not when a worker process (Dask, multiprocessing spawn) imports this module
    main()
