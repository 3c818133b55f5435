"""The ``lensopt`` command line (the top layer: parse options, call the library, render with rich; no physics).

    app.py        the root: the typer app, the commands in ``--help`` order, the global options; nothing
                  imports it but the entry (``lensopt/__main__.py``)
    common.py     consoles, option types and their parsing, --device/--backend, load_model, error
                  rendering (handle_errors, LensoptGroup), print_json, check_output
    signals.py    Ctrl-C / SIGTERM: exit codes 130 / 143 with one line, in every window of the process
    trace.py      trace, ray
    plot.py       plot layout | fans | spots | psf | field | regions | mtf
    formats.py    import-codev, export-codev, import-zemax, export-zemax
    simulate.py   simulate, evaluate
    optimize.py   optimize (live progress, summary)
    restore.py    train-irm, restore; optimize with objective = "restored" (the joint run, torchrun)
    tolerance.py  tolerance
    sweep.py      sweep
    design.py     design (the seed's procedure: multi-start or basin hopping until the best agree)
    qa.py         check, accuracy
    warmup.py     warmup

Command modules import only ``common`` and ``signals`` from here (``optimize`` also calls
``restore.optimize_restored``); each defines ``commands``, a typer app that ``app.py`` puts in order.
"""
