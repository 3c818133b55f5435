"""The ``lensopt`` command line (the top layer: parse options, call the library, render with rich; no physics).

    app.py        the root: the typer app, the commands in ``--help`` order, the global options; nothing
                  imports it but the entry (``lensopt/__main__.py``)
    common.py     consoles, option types and their parsing, --device/--backend, load_model, error
                  rendering (handle_errors, LensoptGroup), print_json, check_output
    signals.py    Ctrl-C / SIGTERM: exit codes 130 / 143 with one line, in every window of the process
    trace.py      trace, ray (``trace_analyses.py``: the tables of trace --wavefront / --seidel)
    plot.py       plot layout | fans | spots | psf | field | regions | mtf
    plot_analyses.py  plot opd | wavefront | field-curves | focal-shift | encircled | mtf-field | through-focus
                  (appended to the plot group by ``app.py``)
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
``restore.optimize_restored``; ``trace`` renders with ``trace_analyses``; ``plot_analyses`` shares ``plot``'s
output options and titles); each defines ``commands``, a typer app that ``app.py`` puts in order.
"""
