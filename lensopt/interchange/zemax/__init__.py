"""Zemax OpticStudio sequential files (.zmx) ↔ lens specs (``lensopt import-zemax`` / ``export-zemax``).

    syntax.py      the operands of a file: system operands and SURF blocks, numbers read (``parse_zmx``)
    materials.py   the glasses of an imported file: AGF catalogs, lensopt's catalogs, model glasses
    system.py      the system data of an imported file: aperture, fields, vignetting, spectrum
    read.py        a .zmx file → a spec (``read_zemax``, ``import_zemax``)
    write.py       a spec → a .zmx file (``write_zemax``, ``export_zemax``)
"""
