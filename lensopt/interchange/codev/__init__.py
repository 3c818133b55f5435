"""CODE V sequence files (.seq) ↔ lens specs (``lensopt import-codev`` / ``export-codev``).

    syntax.py      splitting text into commands; lensopt's extras in comments; derived numbers
    names.py       CODE V glass names ↔ lensopt's catalogs; fictitious glass codes; private names
    materials.py   the materials of an imported file: catalog names, fictitious codes, private catalogs
    system.py      the system data of an imported file: aperture, fields, vignetting, spectrum
    read.py        a .seq file → a spec (``read_codev``, ``import_codev``)
    write.py       a spec → a .seq file (``write_codev``, ``export_codev``)
"""
