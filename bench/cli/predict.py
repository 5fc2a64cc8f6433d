"""``python -m bench predict``: a saved model's torques on a log, and their MSE where the log has torques."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.cli.parser import UsageError
from bench.cli.options import add_plugin, load_plugins
from bench.core.csv_format import read_csv
from bench.core.data import mse
from bench.core.fileio import atomic_write, check_output
from bench.core.modelfile import ModelFileError, read


def add_arguments(p) -> None:
    p.add_argument("--model", type=Path, required=True, help="a model file (python -m bench fit --save, bench select)")
    p.add_argument("--log", type=Path, required=True,
                   help="a CSV in the suite's format (q_i, qd_i, qdd_i, and tau_i where known: python -m bench "
                        "convert makes one from a robot's log)")
    p.add_argument("--out", type=Path, required=True,
                   help="write the predicted torques here: a CSV of tau_hat_1..tau_hat_n, one row per sample of the log")
    p.add_argument("--system", default=None,
                   help="the arm the model was fitted on, where it is not built in: urdf:PATH or measured:PATH (a "
                        "model file names no file that predict opens)")
    add_plugin(p)


def main(args) -> int:
    check_output(args.out)
    header, _ = read(args.model)  # a file that is no model: one line, before anything else is read or imported
    import pandas as pd

    from methods.saving import check_torques, load_model
    from systems import SYSTEMS

    # the arm's URDF or declaration is the user's to name; a method's plugin (code) only where the command line
    # gives it
    names, _ = load_plugins(args, [args.system] if args.system else [])
    given, name = (names or [None])[0], header.get("system")
    if given is not None and name != given:
        raise UsageError(f"{args.model}: the model was fitted on {name!r}, not on --system's {given!r}")
    if name is not None and name not in SYSTEMS:
        files = [p.split(":", 1)[0] for p in header.get("plugins", []) if p.startswith(("urdf:", "measured:"))]
        raise UsageError(f"{args.model}: its system {name!r} is not registered here; name the file that declares it "
                         f"with --system {(files or ['urdf'])[0]}:PATH")
    model, header = load_model(args.model)
    log = read_csv(args.log, dof=int(header["dof"]), system=name, torque_optional=True)
    try:  # the model is the file's: whatever stops it from predicting is the file's fault, said in one line
        tau = np.asarray(model.predict_torque(log), dtype=np.float64)
    except (ArithmeticError, RuntimeError, ValueError, TypeError, IndexError, KeyError, AttributeError) as exc:
        raise ModelFileError(f"{args.model}: its model does not predict on {args.log} "
                             f"({type(exc).__name__}: {exc})"[:300]) from None
    if tau.shape != (len(log), log.dof):
        raise ModelFileError(f"{args.model}: predicts torques of shape {tau.shape} on {len(log)} samples of "
                             f"{log.dof} joints")
    check_torques(tau, header, str(args.model), str(args.log))
    frame = pd.DataFrame(tau, columns=[f"tau_hat_{j + 1}" for j in range(tau.shape[1])])
    atomic_write(args.out, lambda f: frame.to_csv(f, index=False, float_format="%.17g"))
    what = f"{header.get('method')} on {name}" if name else str(header.get("method"))
    print(f"{what}: {len(log)} samples' torques written to {args.out}")
    if not log.meta.get("no_torque"):
        per_joint = np.mean((tau - log.tau) ** 2, axis=0)
        print(f"torque MSE {mse(tau, log.tau):.6g} (per joint: {', '.join(f'{v:.4g}' for v in per_joint)})")
    return 0
