"""Materials (seed S1.1): dispersion models, vendor and design catalogs, and the runtime material objects a
lens is built from. (``tools/generate_glasses.py`` regenerates ``data/glasses.json``.)

    dispersion.py    pure torch dispersion formulas: catalog formulas, Hartmann from nd/vd/ΔPgF
    catalog.py       vendor glasses (``data/``, lazy, cached), name lookup, design catalogs
    agf.py           Zemax AGF glass catalogs: reading them, evaluating their formulas
    material.py      runtime materials (air, catalog, model and tabulated glasses)
    glass_space.py   glass variables: whitened design catalog, pruned Delaunay mesh (S2.1.2, S2.2.4)
"""

from lensopt.materials.catalog import (
    DESIGN_CATALOGS,
    HARTMANN_RANGE_UM,
    VENDORS,
    DesignCatalog,
    Glass,
    design_catalog,
    find_glass,
    list_glasses,
    notice,
    resolve_glass,
)
from lensopt.materials.dispersion import (
    CATALOG_FORMULAS,
    HARTMANN_FORMULA,
    LINE_C_UM,
    LINE_D_UM,
    LINE_F_UM,
    LINE_G_UM,
    catalog_index,
    hartmann_coefficients,
    hartmann_index,
    normal_pgf,
)
from lensopt.materials.material import Air, CatalogGlass, Material, ModelGlass, TabulatedGlass, material_from_name

__all__ = [
    "Air",
    "CATALOG_FORMULAS",
    "CatalogGlass",
    "DESIGN_CATALOGS",
    "DesignCatalog",
    "Glass",
    "HARTMANN_FORMULA",
    "HARTMANN_RANGE_UM",
    "LINE_C_UM",
    "LINE_D_UM",
    "LINE_F_UM",
    "LINE_G_UM",
    "Material",
    "ModelGlass",
    "TabulatedGlass",
    "VENDORS",
    "catalog_index",
    "design_catalog",
    "find_glass",
    "hartmann_coefficients",
    "hartmann_index",
    "list_glasses",
    "material_from_name",
    "normal_pgf",
    "notice",
    "resolve_glass",
]
