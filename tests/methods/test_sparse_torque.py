"""Sparse regression of the torque: it names the friction a joint has, and past a joint's training range its
position terms hold while its friction laws go on."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.core.modelfile import ModelFileError
from methods import METHODS
from methods.saving import load_model, save_model
from tests.methods.test_saving import _contents, _write

VISCOUS, COULOMB, COGGING = (0.7, 0.3), (0.5, 0.9), (0.4, 0.0)


def _joints(n: int, seed: int, reach: float = 1.0) -> Dataset:
    """Two joints on sums of sines; the torque each joint's viscous and Coulomb friction, joint 1's a spring-like
    ``sin q`` term too, with a little noise."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, n)
    q = reach * np.stack([np.sin(0.7 * t + p) + 0.3 * np.sin(2.3 * t) for p in (0.0, 1.0)], axis=1)
    qd = np.gradient(q, t, axis=0)
    tau = np.asarray(VISCOUS) * qd + np.asarray(COULOMB) * np.sign(qd) + np.asarray(COGGING) * np.sin(q)
    return Dataset(q, qd, np.gradient(qd, t, axis=0), tau + 0.01 * rng.standard_normal(tau.shape))


@pytest.fixture(scope="module")
def fitted():
    train = _joints(2000, 0)
    return train, METHODS["sparse_torque"]().fit(train, "indirect", seed=0, budget=Budget(steps=1))


def test_it_names_each_joints_friction_and_predicts_another_trajectory(fitted):
    train, model = fitted
    for j, (b, fc) in enumerate(zip(VISCOUS, COULOMB)):
        names = dict(zip(["1", "sign", "qd", "drag", "q", "sin", "cos"], model.coef[j]))
        assert names["qd"] == pytest.approx(b, rel=0.1) and names["sign"] == pytest.approx(fc, rel=0.1)
    other = _joints(1000, 1, reach=0.9)  # inside the training range
    error = np.mean((model.predict_torque(other) - other.tau) ** 2)
    assert error < 0.02 * np.var(other.tau)


def test_past_a_joints_training_range_its_position_terms_hold_and_its_friction_goes_on(fitted):
    train, model = fitted
    hi = train.q.max(axis=0)
    qd = np.array([[0.4, -0.2], [0.9, -0.6]])

    def at(q, qd):
        return model.predict_torque(Dataset(q, qd, np.zeros_like(q), np.zeros_like(q)))

    # 0.5 rad past the highest position the fit saw, the torque is the one at that end
    np.testing.assert_allclose(at(np.tile(hi + 0.5, (2, 1)), qd), at(np.tile(hi, (2, 1)), qd), rtol=1e-12)
    # and the velocity terms still change it: viscous friction and quadratic drag past the range as inside it
    past = at(np.tile(hi + 0.5, (2, 1)), qd)
    assert np.all(np.abs(past[1] - past[0]) > 0.5 * np.asarray(VISCOUS) * np.abs(qd[1] - qd[0]))
    # inside the range nothing is held
    inside = np.tile(0.5 * hi, (2, 1))
    unheld = model.coef[0] @ np.array([1, 1, qd[0, 0], qd[0, 0] * abs(qd[0, 0]), inside[0, 0], np.sin(inside[0, 0]),
                                       np.cos(inside[0, 0])])
    assert at(inside, qd)[0, 0] == pytest.approx(unheld, rel=1e-12)


def test_a_model_file_keeps_the_range_and_one_with_a_range_upside_down_is_refused(tmp_path, fitted):
    train, model = fitted
    save_model(model, tmp_path / "m.npz", {"system": "double_pendulum", "method": "sparse_torque"}, train, None)
    loaded, _ = load_model(tmp_path / "m.npz")
    np.testing.assert_array_equal(loaded.q_range, model.q_range)
    far = train.replace(q=train.q + 2.0)
    np.testing.assert_array_equal(loaded.predict_torque(far), model.predict_torque(far))
    header, arrays = _contents(tmp_path / "m.npz")
    name = header["model"]["q_range"]["$array"]
    arrays[name] = arrays[name][::-1]  # lowest and highest swapped, the file sealed again
    _write(tmp_path / "m.npz", header, arrays)
    with pytest.raises(ModelFileError, match="m.npz: .*q_range is not each joint's lowest and highest position"):
        load_model(tmp_path / "m.npz")
