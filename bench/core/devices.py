"""Where a torch method trains: ``--device cpu|cuda|auto``.

The device is a property of a run, not a hyperparameter: a method's
configuration is the same on either, and a run's spec names the device it
resolved to (``cpu`` or ``cuda``, never ``auto``), so that a record says
where its numbers were computed and a resume does not take one device's
record for the other's.

Only a torch method (:attr:`methods.base.Method.uses_device`) trains on the
device; evaluation always runs on the CPU in float64, as it does for every
method, so that the scores of a run trained on a GPU are computed exactly as
a CPU run's are.

torch is imported only where ``cuda`` or ``auto`` is asked for, so that a
command that checks ``--device cpu`` and then refuses its input has not
imported it.
"""

from __future__ import annotations

from bench.core.errors import ConfigError

#: what ``--device`` takes
CHOICES = ("cpu", "cuda", "auto")


def resolve(name: str, option: str = "--device") -> str:
    """``cpu`` or ``cuda`` for ``name`` (``auto``: ``cuda`` where torch sees
    one); a :class:`ConfigError` in one line where ``cuda`` is asked for and
    torch sees none, or where ``name`` is not a device."""
    if name not in CHOICES:
        raise ConfigError(f"{option}: one of {', '.join(CHOICES)}, got {name!r}")
    if name == "cpu":
        return name
    import torch

    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        build = "built without CUDA" if torch.version.cuda is None else f"built for CUDA {torch.version.cuda}"
        raise ConfigError(f"{option} cuda: torch {torch.__version__} ({build}) sees no CUDA device on this machine; "
                          f"use {option} cpu or auto")
    return name


def describe(name: str) -> dict:
    """What a record says of the device ``name``: its type and, for ``cuda``,
    the card's model name, torch's CUDA version and its memory (a CPU's model
    is read where the record is made, :func:`bench.runner.provenance.device_entry`)."""
    if name != "cuda":
        return {"type": "cpu"}
    import torch

    index = torch.cuda.current_device()
    return {"type": "cuda", "name": torch.cuda.get_device_name(index), "cuda": torch.version.cuda,
            "memory_gb": round(torch.cuda.get_device_properties(index).total_memory / 2**30, 1)}
