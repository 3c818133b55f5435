"""Checkpoints of long runs (train-irm, joint lens + network optimization): a folder

    CKPT/
      meta.json             kind, step, fingerprint, configs, optimizer hyper-parameters, file hashes
      lens.json             the lens at this step (the resolved-lens JSON of ``lensopt.spec``)
      network.safetensors   network weights
      state.safetensors     optimizer moments, RNG states, LM damping ... (flat named tensors)

No pickle: tensors live in safetensors, everything else in JSON, so loading a checkpoint never runs
code. Writing is atomic (``lensopt.files.atomic_folder``): the folder is written beside the target under a
temporary name, then renamed over it (the previous checkpoint is moved aside first and deleted after). A checkpoint
whose files do not match their recorded SHA-256, or whose fingerprint (lens structure + network
configuration) differs from the run's, is refused with one ``CheckpointError``.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from torch import Tensor

from lensopt.errors import LensoptError
from lensopt.files import atomic_folder

__all__ = ["Checkpoint", "CheckpointError", "save_checkpoint", "load_checkpoint", "fingerprint",
           "flatten_optimizer", "unflatten_optimizer", "lens_structure", "describe_structure", "FORMAT"]

FORMAT = "lensopt-checkpoint-1"
_FILES = ("lens.json", "network.safetensors", "state.safetensors")


class CheckpointError(LensoptError):
    """A checkpoint is missing, corrupt, or was written for another lens structure / network."""


@dataclass
class Checkpoint:
    """Everything needed to continue a run bit-identically.

    Attributes:
        kind: what wrote it (``train-irm`` | ``joint``).
        step: completed steps.
        lens_json: resolved lens (JSON text).
        network: network ``state_dict`` (name → tensor).
        state: other tensors (optimizer moments, generator states, LM state), flat names.
        meta: JSON-serialisable extras (configs, optimizer hyper-parameters, history).
        fingerprint: hash of the lens structure and network configuration.
    """

    kind: str
    step: int
    lens_json: str
    network: dict[str, Tensor]
    state: dict[str, Tensor] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    fingerprint: str = ""


def fingerprint(lens_structure: Any, network_config: Any) -> str:
    """SHA-256 (16 hex digits) of the JSON of the lens structure and the network configuration."""
    text = json.dumps({"lens": lens_structure, "network": network_config}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _sha(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _tensors(d: dict[str, Tensor]) -> dict[str, Tensor]:
    return {k: v.detach().to("cpu").contiguous().clone() for k, v in d.items()}


def save_checkpoint(path: str | os.PathLike[str], ckpt: Checkpoint) -> Path:
    """Write ``ckpt`` to the folder ``path`` atomically (see module doc); return the path."""
    from safetensors.torch import save_file

    target = Path(path)
    if target.exists() and not target.is_dir():
        raise CheckpointError("exists and is not a checkpoint folder", path=str(target))
    with atomic_folder(target) as tmp:
        (tmp / "lens.json").write_text(ckpt.lens_json, encoding="utf-8")
        save_file(_tensors(ckpt.network), str(tmp / "network.safetensors"))
        save_file(_tensors(ckpt.state), str(tmp / "state.safetensors"))
        meta = {"format": FORMAT, "kind": ckpt.kind, "step": ckpt.step, "fingerprint": ckpt.fingerprint,
                "meta": ckpt.meta, "sha256": {n: _sha(tmp / n) for n in _FILES}}
        (tmp / "meta.json").write_text(json.dumps(meta, indent=1, sort_keys=True), encoding="utf-8")
    return target


def load_checkpoint(path: str | os.PathLike[str], *, expect_fingerprint: str | None = None,
                    option: str = "CKPT") -> Checkpoint:
    """Read and verify a checkpoint folder; ``CheckpointError`` (one line) if anything is wrong."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    src = Path(path)
    if not src.is_dir():
        raise CheckpointError("no such checkpoint folder" if not src.exists() else "not a checkpoint folder",
                              path=option, got=str(src))
    try:
        meta = json.loads((src / "meta.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CheckpointError("not a lensopt checkpoint (no meta.json)", path=option, got=str(src)) from None
    except (OSError, ValueError) as err:
        raise CheckpointError(f"corrupt checkpoint: meta.json unreadable ({err})", path=option) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"not a {FORMAT} checkpoint", path=option, got=str(src))
    for n in _FILES:
        if not (src / n).is_file():
            raise CheckpointError(f"corrupt checkpoint: {n} is missing", path=option, got=str(src))
        if _sha(src / n) != meta.get("sha256", {}).get(n):
            raise CheckpointError(f"corrupt checkpoint: {n} does not match its recorded SHA-256", path=option,
                                  got=str(src))
    if expect_fingerprint is not None and meta.get("fingerprint") != expect_fingerprint:
        raise CheckpointError("was written for another lens structure or network configuration "
                              f"(fingerprint {meta.get('fingerprint')}, this run {expect_fingerprint})", path=option,
                              got=str(src))
    try:
        network = load_file(str(src / "network.safetensors"))
        state = load_file(str(src / "state.safetensors"))
    except (SafetensorError, OSError, ValueError) as err:
        raise CheckpointError(f"corrupt checkpoint: {err}", path=option) from None
    return Checkpoint(kind=meta["kind"], step=int(meta["step"]), lens_json=(src / "lens.json").read_text("utf-8"),
                      network=network, state=state, meta=meta.get("meta", {}), fingerprint=meta.get("fingerprint", ""))


def flatten_optimizer(prefix: str, state_dict: dict[str, Any]) -> tuple[dict[str, Tensor], dict[str, Any]]:
    """A torch optimizer ``state_dict`` → (flat tensors ``prefix.i.key``, JSON part: param groups and
    non-tensor per-parameter values)."""
    tensors: dict[str, Tensor] = {}
    scalars: dict[str, Any] = {}
    for i, st in state_dict["state"].items():
        for k, v in st.items():
            if isinstance(v, Tensor):
                tensors[f"{prefix}.{i}.{k}"] = v
            else:
                scalars[f"{i}.{k}"] = v
    return tensors, {"param_groups": state_dict["param_groups"], "scalars": scalars}


def unflatten_optimizer(prefix: str, tensors: dict[str, Tensor], info: dict[str, Any]) -> dict[str, Any]:
    """Inverse of ``flatten_optimizer`` (betas come back as tuples, as torch writes them)."""
    state: dict[int, dict[str, Any]] = {}
    for name, v in tensors.items():
        if name.startswith(prefix + "."):
            i, k = name[len(prefix) + 1:].split(".", 1)
            state.setdefault(int(i), {})[k] = v
    for name, v in info.get("scalars", {}).items():
        i, k = name.split(".", 1)
        state.setdefault(int(i), {})[k] = v
    groups = [{k: tuple(v) if k == "betas" else v for k, v in g.items()} for g in info["param_groups"]]
    return {"state": state, "param_groups": groups}



def lens_structure(spec: Any) -> dict[str, Any]:
    """What must match for a network to fit a lens: surface kinds, the stop, the number of wavelengths.

    Radii, thicknesses, glasses and ``vary`` lists change during design and are not part of it.
    ``spec`` is a ``lensopt.spec.LensSpec`` (read by attribute)."""
    return {
        "surfaces": [[s.type, bool(s.stop)] for s in spec.surfaces],
        "wavelengths": len(spec.spectrum.wavelengths_nm),
    }


def describe_structure(structure: dict[str, Any] | None) -> str:
    """``lens_structure``'s dict in a few words: ``5 surfaces (standard×4, image), stop at 2, 12 wavelengths``."""
    if not structure:
        return "an unrecorded lens structure"
    surfaces = structure.get("surfaces", [])
    kinds: list[str] = []
    for kind, _ in surfaces:
        if kinds and kinds[-1].split("×")[0] == kind:
            head, _, n = kinds[-1].partition("×")
            kinds[-1] = f"{head}×{int(n or 1) + 1}"
        else:
            kinds.append(kind)
    stops = [i for i, (_, stop) in enumerate(surfaces) if stop]
    stop = f", stop at {stops[0]}" if stops else ""
    return f"{len(surfaces)} surfaces ({', '.join(kinds)}){stop}, {structure.get('wavelengths')} wavelengths"
