"""Checkpoints of restoration networks (``lensopt.checkpoint`` holds the format): the fingerprint that
ties a network to a lens structure, the state of a training run (weights, Adam moments, generator
states, history) and back, ``--resume`` of a ``train-irm`` run with the same settings, and loading a
trained network for a lens."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from lensopt.checkpoint import (
    Checkpoint,
    CheckpointError,
    describe_structure,
    fingerprint,
    flatten_optimizer,
    lens_structure,
    load_checkpoint,
    save_checkpoint,
    unflatten_optimizer,
)
from lensopt.restore.config import RestoreConfig
from lensopt.restore.model import ConditionedRestorer

NetworkRun = Any
"""A ``restore.train.NetworkRun`` (model, optimizer, generators, step, history); typed loosely here so that
the training loop can import this module."""

__all__ = ["network_fingerprint", "run_state", "load_run_state", "resume_run", "load_network", "ship_network"]


def network_fingerprint(spec: Any, net: RestoreConfig) -> str:
    """What a checkpoint of network ``net`` for the lens of ``spec`` must match (lens structure + network)."""
    return fingerprint(lens_structure(spec), net.to_dict())


def run_state(run: NetworkRun, prefix: str = "adam") -> tuple[dict[str, Tensor], dict[str, Tensor], dict[str, Any]]:
    """(network weights, other tensors, JSON part) of ``run`` for ``lensopt.checkpoint``."""
    model = getattr(run.model, "module", run.model)  # unwrap DDP
    opt_t, opt_info = flatten_optimizer(prefix, run.optimizer.state_dict())
    state = dict(opt_t)
    state.update({f"rng.{k}": g.get_state() for k, g in run.generators.items()})
    return dict(model.state_dict()), state, {prefix: opt_info, "history": run.history}


def load_run_state(run: NetworkRun, network: dict[str, Tensor], state: dict[str, Tensor], info: dict[str, Any],
                   step: int, prefix: str = "adam") -> None:
    """Put a checkpoint's weights, Adam moments, generator states and step into ``run``."""
    model = getattr(run.model, "module", run.model)
    device = next(model.parameters()).device
    try:
        model.load_state_dict({k: v.to(device) for k, v in network.items()})
        run.optimizer.load_state_dict(unflatten_optimizer(prefix, {k: v.to(device) for k, v in state.items()},
                                                          info[prefix]))
        for k, g in run.generators.items():
            g.set_state(state[f"rng.{k}"])
    except (KeyError, RuntimeError, ValueError) as err:
        raise CheckpointError(f"does not fit this network: {str(err).splitlines()[0]}", path="--resume") from None
    run.step = step
    run.history = list(info.get("history", []))


def resume_run(run: NetworkRun, output: Path, fp: str, settings: dict[str, Any]) -> None:
    """Continue ``run`` from the ``train-irm`` checkpoint at ``output``, refused unless it was written for
    this network and lens (``fp``) with the same trajectory ``settings``."""
    ck = load_checkpoint(output, expect_fingerprint=fp, option="--resume")
    if ck.kind != "train-irm":
        raise CheckpointError(f"is a {ck.kind} checkpoint, not train-irm", path="--resume", got=str(output))
    if ck.meta.get("settings") != json.loads(json.dumps(settings)):
        old = ck.meta.get("settings", {})
        diff = sorted(k for part in ("imaging", "train") for k in set(old.get(part, {})) | set(settings[part])
                      if old.get(part, {}).get(k) != settings[part].get(k))
        if old.get("data") != settings["data"]:
            diff.append("images")
        raise CheckpointError(f"was written with other settings ({', '.join(diff)}); resume with the same ones",
                              path="--resume", got=str(output))
    load_run_state(run, ck.network, ck.state, ck.meta, ck.step)


def load_network(path: Path, spec: Any, *, device: torch.device | str = "cpu",
                 option: str = "CKPT") -> tuple[ConditionedRestorer, Checkpoint]:
    """The network of a checkpoint, refused unless it was written for this lens structure."""
    probe = load_checkpoint(path, option=option)
    net = RestoreConfig.from_dict(probe.meta.get("network_config", {}))
    fp = network_fingerprint(spec, net)
    if probe.fingerprint != fp:
        mine = lens_structure(spec)
        theirs = probe.meta.get("lens_structure")
        raise CheckpointError(f"its network was trained for {describe_structure(theirs)}, but the lens has "
                              f"{describe_structure(mine)} (surface kinds, stop and number of wavelengths must match)",
                              path=option, got=str(path))
    model = ConditionedRestorer(net).to(device)
    try:
        model.load_state_dict({k: v.to(device) for k, v in probe.network.items()})
    except RuntimeError as err:
        raise CheckpointError(f"weights do not fit the network: {str(err).splitlines()[0]}", path=option) from None
    model.eval()
    return model, probe


SHIPPED_META = ("colour", "lens_structure", "network_config", "settings")


def ship_network(src: Path, dst: Path, *, lens: str, dtype: torch.dtype = torch.float16) -> Path:
    """A trained network as a small checkpoint for ``lensopt restore`` / ``evaluate --irm`` / ``tolerance
    --irm``: the weights in ``dtype`` (loaded back into the float32 network), no Adam moments, generator
    states or per-step history (so it cannot be ``--resume``d). Its metadata keep the fingerprint (lens
    structure + network), colour, network and training settings, and add ``lens`` (the shipped lens it
    belongs to), ``lens_sha256`` (of the lens JSON it was trained for, also ``lens.json`` in the folder),
    ``steps``, ``last_validation`` and ``weights_dtype``."""
    import hashlib

    ck = load_checkpoint(src)
    meta: dict[str, Any] = {k: ck.meta[k] for k in SHIPPED_META if k in ck.meta}
    hist = ck.meta.get("history") or []
    meta.update({"lens": lens, "lens_sha256": hashlib.sha256(ck.lens_json.encode()).hexdigest(), "steps": ck.step,
                 "last_validation": next((h for h in reversed(hist) if "psnr_restored" in h), None),
                 "weights_dtype": str(dtype).removeprefix("torch.")})
    weights = {k: v.to(dtype) if v.is_floating_point() else v for k, v in ck.network.items()}
    return save_checkpoint(dst, Checkpoint(kind=ck.kind, step=ck.step, lens_json=ck.lens_json, network=weights,
                                           meta=meta, fingerprint=ck.fingerprint))
