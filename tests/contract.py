"""The checks every registered method and system must pass.

Used by the parametrised tests over the registries and by the extension test
for methods and systems registered outside the suite.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import sympy
import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from bench.core import symbolic
from bench.core.budget import Budget, Schedule
from bench.core.data import Dataset, generate
from bench.physics.models import FittedModel, mass_and_bias
from methods.stacking import fit_stacked
from systems import SYSTEMS, Domain
from bench.core.scoring import opened
from bench.core.sealed import SealedSplit


def suite_entries(registry, package: str) -> list[str]:
    """Names registered by the suite's own modules (not by tests or plugins)."""
    return [e.name for e in registry.entries() if e.obj.__module__.startswith(package + ".")]


def check_system(system) -> None:
    assert system.dof == len(system.coordinates) >= 1
    assert dataclasses.is_dataclass(system.params)
    assert isinstance(system.domain, Domain)
    assert set(system.experiments) <= {"direct", "indirect"} and system.experiments
    if not system.simulated:
        return check_measured_system(system)
    if system.symbolic:
        check_symbolic_lagrangian(system)
    else:
        check_engine_system(system)
    check_generated_data(system)


def check_symbolic_lagrangian(system) -> None:
    """The sympy Lagrangian, its torch function and its parametric form agree."""
    q, qd = system.symbols
    expr = system.lagrangian_sympy
    assert expr.free_symbols <= set(q) | set(qd)
    assert expr.free_symbols & set(qd), "a Lagrangian without velocities has no dynamics"

    rng = np.random.default_rng(0)
    Q, QD = rng.uniform(-1.5, 1.5, (64, system.dof)), rng.uniform(-1.5, 1.5, (64, system.dof))
    truth = symbolic.to_numpy(expr, system.dof)(Q, QD)
    got = system.lagrangian(torch.from_numpy(Q), torch.from_numpy(QD)).numpy()
    np.testing.assert_allclose(got, truth, rtol=1e-12, atol=1e-12)

    form = system.parametric_form()
    assert len(form.unknowns) == len(set(form.unknowns)) >= 1
    at_truth = symbolic.to_numpy(form.substitute(form.true_values), system.dof)(Q, QD)
    np.testing.assert_allclose(at_truth, truth, rtol=1e-12, atol=1e-12)
    theta = torch.tensor(form.true_values, dtype=torch.float64)
    via_torch = form.torch_fn(torch.from_numpy(Q), torch.from_numpy(QD), theta).numpy()
    np.testing.assert_allclose(via_torch, truth, rtol=1e-12, atol=1e-12)


def check_engine_system(system) -> None:
    """An engine-backed system: its linear form reproduces its torques and L,
    and its kinetic energy agrees with the mass matrix its torques imply."""
    assert system.lagrangian_sympy is None
    data = generate(system, 64, 5, cache=False)
    form = system.linear_form()
    pi = np.asarray(form.true_values)
    assert len(form.names) == len(set(form.names)) == len(pi) >= 1
    Y = form.torque_regressor(data.q, data.qd, data.qdd)
    assert Y.shape == (64, system.dof, len(pi))
    np.testing.assert_allclose(Y @ pi, data.tau, rtol=1e-9, atol=1e-9 * np.abs(data.tau).max())
    np.testing.assert_allclose(form.lagrangian_regressor(data.q, data.qd) @ pi, data.L, rtol=1e-9,
                               atol=1e-9 * np.abs(data.L).max())
    # T = qd^T M qd / 2, with M from the torques' dependence on qdd, and V from L at rest
    M, _ = mass_and_bias(TorquesOf(system), data.q, data.qd)
    kinetic = 0.5 * np.einsum("ni,nij,nj->n", data.qd, M, data.qd)
    at_rest = system.lagrangian(torch.from_numpy(data.q), torch.zeros_like(torch.from_numpy(data.qd))).numpy()
    np.testing.assert_allclose(kinetic + at_rest, data.L, rtol=1e-9, atol=1e-9 * np.abs(data.L).max())
    assert np.all(np.linalg.eigvalsh(M)[:, 0] > 0)
    accelerations = system.forward_dynamics(data.q, data.qd)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", M, accelerations), -_bias(system, data), rtol=1e-8, atol=1e-8)


class TorquesOf(FittedModel):
    """A system's own torques as a model (for :func:`mass_and_bias`)."""

    def __init__(self, system):
        self.system = system

    def predict_lagrangian(self, data):
        t = data.tensors()
        return self.system.lagrangian(t["q"], t["qd"]).numpy()

    def predict_torque(self, data):
        t = data.tensors()
        return self.system.torque(t["q"], t["qd"], t["qdd"])[0].numpy()


def _bias(system, data) -> np.ndarray:
    t = data.tensors()
    return system.torque(t["q"], t["qd"], torch.zeros_like(t["qdd"]))[0].numpy()


def check_generated_data(system) -> None:
    """Generated data are a pure function of the seed, inside the domain, finite."""
    if system.simulated:
        a, b = generate(system, 200, 11, cache=False), generate(system, 200, 11, cache=False)
        c = generate(system, 200, 12, cache=False)
        for k in ("q", "qd", "qdd", "tau"):
            arr = getattr(a, k)
            assert arr.shape == (200, system.dof) and np.isfinite(arr).all()
            if k != "tau":
                lo, hi = system.domain.bounds(k, system.dof)
                assert (arr >= lo).all() and (arr <= hi).all()
            assert np.array_equal(arr, getattr(b, k))
        assert not np.array_equal(a.q, c.q)
        assert a.L.shape == (200,) and np.isfinite(a.L).all()


def one_system_per_kind(names: list[str]) -> list[str]:
    """The first of ``names`` of each kind of data a system gives: a closed-form
    simulation, an engine's simulation (no symbolic L), a measurement. What a
    method does on its device depends on its code and on that kind (the data's
    shapes, times, trajectories), not on which system of a kind gave them, so
    the device check (:func:`check_device`, a whole fit with every op checked,
    about fifteen times a plain fit's time) runs on these, and so does the
    check of a symbolic method's written-out expression (sympy builds SyReNets'
    network term for term: seconds on a seven-joint arm, each time)."""
    kinds = {}
    for name in names:
        cls = SYSTEMS[name]
        kinds.setdefault((cls.simulated, cls.simulated and cls.symbolic), name)
    return list(kinds.values())


def check_method(cls, train: Dataset, test: Dataset, experiment: str, device: bool = True) -> None:
    """``cls`` on ``train`` and ``test``: it fits within its smoke configuration's
    steps, replays and predicts finite values; with ``device`` (on one system of
    each kind, :func:`one_system_per_kind`), its fit keeps to its device
    (:func:`check_device`) and, where symbolic, it writes out its model as the
    expression it predicts with."""
    smoke = cls.smoke_config()
    assert smoke, f"{cls.name} declares no smoke configuration"
    assert smoke.get("max_steps"), "a smoke configuration must bound its steps, so that a seed is reproducible"

    m = cls(**smoke).fit(train, experiment, seed=0, budget=Budget(steps=smoke["max_steps"]))  # a work budget: no deadline
    L, tau = m.predict_lagrangian(test), m.predict_torque(test)
    assert L.shape == (len(test),) and tau.shape == (len(test), train.dof)
    assert np.isfinite(tau).all() and (np.isfinite(L).all() if cls.has_lagrangian else np.isnan(L).all())
    info = m.fit_info
    assert 0 < info["steps"] <= smoke["max_steps"]
    assert info["curve"] and all(b <= a for (_, a), (_, b) in zip(info["curve"], info["curve"][1:]))
    # the same seed and the work the fit recorded give the same result (what python -m bench rerun does)
    replay = info["schedule"]
    if "unavailable" not in replay:
        again = cls(**smoke).fit(train, experiment, seed=0, budget=Budget.replaying(Schedule.from_json(replay)))
        np.testing.assert_array_equal(again.predict(test), m.predict(test))
        assert again.fit_info["steps"] == info["steps"]
    if device and cls.uses_device and experiment == "indirect":  # the torque loss has every part of a step
        check_device(cls, train, experiment)
    if cls(**smoke).stacking_unavailable_reason() is None:
        check_stacked(cls, smoke, train, test, experiment, first=m)
    if not device:
        return
    expr = m.expression()
    engine = train.system in SYSTEMS and not SYSTEMS[train.system].symbolic
    if "symbolic" in cls.tags and not (engine and "parametric" in cls.tags):  # SysId fits an engine's regressor
        assert isinstance(expr, sympy.Expr)
        f = symbolic.to_numpy(expr, train.dof)
        np.testing.assert_allclose(f(test.q, test.qd), L, rtol=1e-9, atol=1e-9)
    else:
        assert expr is None


def check_stacked(cls, smoke: dict, train: Dataset, test: Dataset, experiment: str, first=None) -> None:
    """Two seeds stacked in one model (``--stack-seeds``) give the fits each seed
    makes alone: to the last bits in float64, to float32's rounding otherwise
    (the stack's batched products sum in another order). ``first``: seed 0's
    fit alone on ``train`` in ``smoke`` where the caller has made it."""
    seeds = [0, 1]
    alone = [first if k == 0 and first is not None else
             cls(**smoke).fit(train, experiment, seed=k, budget=Budget(steps=smoke["max_steps"])) for k in seeds]
    stacked = fit_stacked([cls(**smoke) for _ in seeds], [train, train], experiment, seeds, budget=Budget(steps=smoke["max_steps"]))
    tolerance = 1e-12 if getattr(alone[0].config, "dtype", "float64") == "float64" else 1e-5
    for a, b in zip(alone, stacked):
        want, got = a.predict(test), b.predict(test)
        assert np.max(np.abs(got - want)) <= tolerance * np.max(np.abs(want)), (
            f"{cls.name}: a stacked seed's fit is not the fit it makes alone; a method whose loss is not "
            f"the stacked loop's must say why it cannot stack (stacking_unavailable_reason)")
        assert b.fit_info["steps"] == a.fit_info["steps"]


def check_measured_system(system) -> None:
    """A measured system: each of its splits loads, agrees on the coordinates, and holds
    its test trajectories out of training; its form for SysId claims no true values."""
    for split in system.splits:
        train, test = (type(system)(split=split).load(part) for part in ("train", "test"))
        assert isinstance(test, SealedSplit) and not isinstance(train, SealedSplit)  # read only to score
        test = opened(test)
        for data in (train, test):
            assert len(data) > 0 and data.dof == system.dof and data.system == system.name
            for k in ("q", "qd", "qdd", "tau"):
                assert np.isfinite(getattr(data, k)).all()
        assert not np.isin(test.q[:, 0], train.q[:, 0]).all()
        assert not set(train.trajectories()) & set(test.trajectories())
        if "direct" not in system.experiments:
            assert train.L is None and system.not_applicable
    linear = system.linear_form()
    if linear is not None:
        assert linear.true_values is None and len(linear.names) >= 1
        return
    form = system.parametric_form()
    assert form.true_values is None and len(form.unknowns) >= 1



class OnMeta(TorchDispatchMode):
    """Stands in for a GPU on a machine without one: every torch op of a fit
    on the ``meta`` device (tensors with shapes and no values) is checked to
    take all its tensors on one device, as CUDA requires. ``.item()`` of a meta
    tensor gives 1.0 and a copy to the CPU gives zeros, so that a whole fit
    runs; a tensor the method left on the CPU shows as an op with mixed
    devices (:attr:`mixed`), whether or not torch itself would refuse it."""

    #: ops that move a tensor between devices, or index one with the CPU's indices (which CUDA allows)
    ALLOWED = {torch.ops.aten._to_copy.default, torch.ops.aten.copy_.default, torch.ops.aten.index.Tensor,
               torch.ops.aten.index_put_.default, torch.ops.aten.index_put.default,
               torch.ops.aten._index_put_impl_.default}

    def __init__(self):
        super().__init__()
        self.mixed, self.on_meta = set(), 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        tensors = [a for a in tree_leaves((args, kwargs)) if isinstance(a, torch.Tensor)]
        if any(t.device.type == "meta" for t in tensors):
            self.on_meta += 1
            if func is torch.ops.aten._local_scalar_dense.default:
                return 1.0
            if func is torch.ops.aten._to_copy.default and torch.device(kwargs.get("device") or "meta").type == "cpu":
                return torch.zeros(args[0].shape, dtype=kwargs.get("dtype") or args[0].dtype)
        if len({t.device.type for t in tensors if t.dim() > 0}) > 1 and func not in self.ALLOWED:
            self.mixed.add(str(func))
        return func(*args, **kwargs)


def check_device(cls, train: Dataset, experiment: str) -> None:
    """A method that trains on a run's device (``--device``) keeps every tensor of
    its fit there (checked on the ``meta`` device, :class:`OnMeta`) and ends on
    the CPU, where fits are evaluated; any other method stays on the CPU."""
    smoke = cls.smoke_config()
    if not cls.uses_device:
        assert cls(**smoke).use_device("cuda").train_device == "cpu"
        return
    method = cls(**smoke).use_device("meta")
    mode = OnMeta()
    with mode:
        method.fit(train, experiment, seed=0, budget=Budget(steps=smoke["max_steps"]))
    assert not mode.mixed, f"{cls.name} mixed devices in {sorted(mode.mixed)}"
    if method.trained_on() == "meta":  # else it had nothing to train there (SysId solving an arm's linear form)
        assert mode.on_meta > 10 * smoke["max_steps"], f"{cls.name} did not train on its device"
    else:
        assert method.trained_on() == "cpu" and mode.on_meta == 0
    tau = method.predict_torque(train.subset(slice(0, 8)))  # evaluated on the CPU: real numbers, not meta zeros
    assert tau.shape == (8, train.dof) and np.isfinite(tau).all()
