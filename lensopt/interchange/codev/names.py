"""CODE V material names: catalog glasses (``NBK7_SCHOTT``), fictitious glass codes, private names.

CODE V names a catalog glass by the vendor's name without hyphens or spaces and the catalog after
an underscore: Schott N-BK7 is ``NBK7_SCHOTT``, Ohara S-LAL8 is ``SLAL8_OHARA`` (as in the CODE V
files Edmund Optics publishes, e.g. ``CODV_49664.seq``: ``SLAL8_OHARA``, ``STIH53_OHARA``).
Fictitious glasses are written as codes: ``516800.641700`` is n_d = 1.516800, V_d = 64.1700 (integer
part = (n_d − 1)·10^k, fraction = V_d/100), and the six-digit MIL code ``517642`` is n_d = 1.517,
V_d = 64.2.
"""

from __future__ import annotations

import functools
import re

from lensopt.errors import MaterialError
from lensopt.materials.catalog import PLASTICS_VENDOR, VENDORS, Glass, find_glass, list_glasses

__all__ = [
    "CODEV_CATALOGS",
    "codev_key",
    "codev_glass_name",
    "find_codev_glass",
    "fictitious_glass",
    "private_name",
]

#: lensopt vendor -> CODE V catalog suffix.
CODEV_CATALOGS: dict[str, str] = {v: v.upper() for v in VENDORS if v != PLASTICS_VENDOR}

_FICTITIOUS_RE = re.compile(r"^(\d{3,})\.(\d+)$")
_MIL_RE = re.compile(r"^(\d{3})(\d{3})$")


def codev_key(name: str) -> str:
    """A glass name as CODE V spells it: upper case, letters and digits only (``N-BK7`` -> ``NBK7``)."""
    return re.sub(r"[^0-9A-Z]", "", name.upper())


@functools.cache
def _codev_index() -> dict[str, dict[str, Glass | None]]:
    """vendor -> CODE V key -> Glass (None where two glasses of a vendor share a key)."""
    out: dict[str, dict[str, Glass | None]] = {}
    for vendor in CODEV_CATALOGS:
        table: dict[str, Glass | None] = {}
        for glass in list_glasses(vendor):
            key = codev_key(glass.name)
            table[key] = None if key in table else glass
        out[vendor] = table
    return out


def codev_glass_name(glass: Glass) -> str:
    """CODE V name of a catalog glass (``NBK7_SCHOTT``).

    Raises:
        MaterialError: the glass has no CODE V catalog (the seed's plastics) or its name is ambiguous
            once hyphens are dropped; export it through a private catalog instead.
    """
    if glass.vendor not in CODEV_CATALOGS:
        raise MaterialError(f"{glass.label} has no CODE V catalog; it is exported as a private glass",
                            got=glass.name)
    key = codev_key(glass.name)
    if _codev_index()[glass.vendor].get(key) is not glass:
        raise MaterialError(f"{glass.label} is ambiguous in CODE V spelling {key}", got=glass.name)
    return f"{key}_{CODEV_CATALOGS[glass.vendor]}"


def find_codev_glass(name: str) -> Glass:
    """The catalog glass a CODE V material name means (``NBK7_SCHOTT``, ``SK16``, ``N-BK7_SCHOTT``).

    Without a catalog suffix the vendors are searched in lensopt's priority order (schott first).

    Raises:
        MaterialError: unknown catalog or glass; the message lists close catalog matches.
    """
    base, sep, catalog = name.strip().rpartition("_")
    if not sep:
        base, catalog = name.strip(), ""
    vendors: tuple[str, ...] = tuple(CODEV_CATALOGS)
    if catalog:
        vendor = catalog.lower()
        if vendor not in CODEV_CATALOGS:
            raise MaterialError(f"unknown CODE V glass catalog {catalog!r} in {name!r}; lensopt knows "
                                + ", ".join(CODEV_CATALOGS.values()), got=name)
        vendors = (vendor,)
    key = codev_key(base)
    for vendor in vendors:
        glass = _codev_index()[vendor].get(key)
        if glass is not None:
            return glass
    # Not found: let the catalog lookup say what is close (it raises with close matches).
    guess = _hyphenated(base, vendors[0]) if len(vendors) == 1 else base
    try:
        glass = find_glass(f"{vendors[0]}:{guess}" if len(vendors) == 1 else guess)
    except MaterialError as err:
        raise MaterialError(f"CODE V glass {name!r}: {err.message}", got=name) from None
    if glass.vendor in vendors:
        return glass
    raise MaterialError(f"CODE V glass {name!r} is not in lensopt's catalogs", got=name)


def _hyphenated(base: str, vendor: str) -> str:
    """Best guess of the vendor spelling of a CODE V key (``NBK7`` -> ``N-BK7``) for suggestions."""
    if vendor in ("schott", "ohara", "sumita", "cdgm") and len(base) > 2 and base[0] in "NPSLKDH":
        return f"{base[0]}-{base[1:]}"
    return base


def fictitious_glass(token: str) -> tuple[float, float] | None:
    """(n_d, V_d) of a CODE V fictitious glass code, or None when ``token`` is not one.

    ``516800.641700`` -> (1.5168, 64.17): the integer part holds the digits of n_d − 1, the fraction
    V_d / 100. A six-digit MIL code ``517642`` -> (1.517, 64.2).
    """
    text = token.strip()
    m = _FICTITIOUS_RE.match(text)
    if m:
        digits, frac = m.groups()
        return 1.0 + int(digits) / 10 ** len(digits), round(100.0 * float(f"0.{frac}"), 10)
    m = _MIL_RE.match(text)
    if m:
        return 1.0 + int(m.group(1)) / 1000.0, int(m.group(2)) / 10.0
    return None


def private_name(label: str, taken: set[str]) -> str:
    """A private-catalog glass name from ``label``: letters and digits only, prefixed ``LO`` so that no
    reader mistakes it for a catalog glass, unique among ``taken`` (which it is added to)."""
    base = "LO" + (codev_key(label) or "GLASS")[:14]
    name, k = base, 2
    while name in taken:
        name, k = f"{base}{k}", k + 1
    taken.add(name)
    return name
