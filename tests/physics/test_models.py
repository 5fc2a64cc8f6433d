"""The one fitted-model interface: abstract where it must be, and the
expression-backed and parametric models against independent evaluations."""

from __future__ import annotations

import numpy as np
import pytest
import sympy

from bench.core import symbolic
from bench.core.data import generate
from bench.physics.models import ExpressionModel, FittedModel, ParametricModel
from bench.physics.system import ParametricForm
from methods import METHODS, Method
from systems import get_system
from bench.core.budget import Budget


def test_the_interface_and_the_method_hooks_are_abstract():
    with pytest.raises(TypeError, match="predict_lagrangian"):
        FittedModel()

    class NoLoop(Method):
        def _get_state(self):
            return None

        def _set_state(self, state):
            pass

        def predict_lagrangian(self, data):
            return np.zeros(len(data))

        def predict_torque(self, data):
            return np.zeros_like(data.tau)

    with pytest.raises(TypeError, match="_fit"):
        NoLoop()


def test_an_expression_model_predicts_its_lagrangian_and_torques():
    system = get_system("double_pendulum")
    data = generate(system, 200, 3)
    model = ExpressionModel(system.lagrangian_sympy, 2)
    np.testing.assert_allclose(model.predict_lagrangian(data), data.L, rtol=1e-12)
    np.testing.assert_allclose(model.predict_torque(data), data.tau, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(model.predict(data, "direct"), model.predict_lagrangian(data))
    assert model.expression() == system.lagrangian_sympy and model.parametric() is None


def test_a_parametric_model_at_the_true_values_is_the_system():
    system = get_system("double_pendulum")
    data = generate(system, 200, 4)
    form = system.parametric_form()
    model = ParametricModel(form, form.true_values)
    np.testing.assert_allclose(model.predict_torque(data), data.tau, rtol=1e-10, atol=1e-10)
    assert model.parameters() == dict(zip(system.sysid_unknowns, form.true_values))
    residual = sympy.expand(model.expression() - system.lagrangian_sympy)
    assert all(abs(float(c)) < 1e-12 for c in residual.as_coefficients_dict().values())


def test_the_parameter_jacobian_of_a_form_linear_in_its_parameters():
    # L = m qd^2/2 - k q^2/2: d tau / d m = qdd and d tau / d k = q, exactly
    system = get_system("single_pendulum")
    (q,), (qd,) = symbolic.coordinate_symbols(1)
    m, k = sympy.symbols("m k", real=True)
    form = ParametricForm(m * qd**2 / 2 - k * q**2 / 2, (m, k), 1, (2.0, 5.0))
    data = generate(system, 100, 5)
    J = ParametricModel(form, [2.0, 5.0]).jacobian(data)
    np.testing.assert_allclose(J[:, 0], data.qdd.ravel(), rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(J[:, 1], data.q.ravel(), rtol=1e-7, atol=1e-9)


def test_sysid_gives_its_fit_as_a_parametric_model():
    system = get_system("double_pendulum")
    data = generate(system, 256, 6)
    sysid = METHODS["sysid"](max_steps=5).fit(data, "indirect", 0, Budget(seconds=10.0))
    model = sysid.parametric()
    assert isinstance(model, ParametricModel) and model.parameters() == sysid.identified_parameters()
    np.testing.assert_allclose(model.predict_torque(data), sysid.predict_torque(data), rtol=1e-10, atol=1e-10)
    assert METHODS["mlp"](max_steps=1, hidden=4, layers=1).fit(data, "indirect", 0, Budget(seconds=5.0)).parametric() is None


@pytest.mark.parametrize("name", ["double_pendulum", "dfki_double_pendulum", "cart_pole", "spring_pendulum", "delan_characters"])
def test_a_separated_form_gives_the_torch_functions_torques_and_an_exact_jacobian(name):
    """tau(theta) = sum_k c_k(theta) g(phi_k): against the form's torch function
    through the transform, and the Jacobian against central differences of it."""
    from bench.physics.models import LagrangianFunction, separate

    s = get_system(name)
    form = s.parametric_form()
    sep = separate(form)
    assert sep is not None and len(sep.basis) <= 12
    theta = np.random.default_rng(1).uniform(0.5, 2.0, len(form.unknowns))
    model = ParametricModel(form, theta)
    data = generate(s, 300, 0) if s.simulated else s.load("train").subset(np.arange(300))
    direct = LagrangianFunction.predict_torque(model, data)  # the torch function, through the transform
    np.testing.assert_allclose(model.predict_torque(data), direct, rtol=1e-12, atol=1e-12 * np.abs(direct).max())
    np.testing.assert_allclose(model.predict_lagrangian(data), LagrangianFunction.predict_lagrangian(model, data),
                               rtol=1e-12, atol=1e-12)
    columns = []
    for i, value in enumerate(theta):
        h = 1e-6 * max(1.0, abs(value))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        columns.append((LagrangianFunction.predict_torque(model.with_parameters(up), data)
                        - LagrangianFunction.predict_torque(model.with_parameters(down), data)).ravel() / (2 * h))
    differences = np.stack(columns, axis=1)
    np.testing.assert_allclose(model.jacobian(data), differences, rtol=1e-6, atol=1e-6 * np.abs(differences).max())


def test_a_form_whose_unknown_sits_inside_a_function_of_the_coordinates_is_not_separated():
    from bench.physics.models import separate

    (q,), (qd,) = symbolic.coordinate_symbols(1)
    w = sympy.Symbol("w")
    form = ParametricForm(qd**2 / 2 + sympy.cos(w * q), (w,), 1, (2.0,))
    assert separate(form) is None
    model = ParametricModel(form, [2.0])
    data = generate(get_system("single_pendulum"), 50, 0)
    np.testing.assert_allclose(model.predict_torque(data)[:, 0], data.qdd[:, 0] + 2.0 * np.sin(2.0 * data.q[:, 0]),
                               rtol=1e-12, atol=1e-12)
    assert model.jacobian(data).shape == (50, 1)  # central differences


def test_a_linear_models_regressor_is_computed_once_per_data_set():
    import dataclasses

    from bench.core.data import generate
    from bench.physics.linear import LinearParametricModel
    from bench.physics.system import LinearForm

    calls = []

    def regressor(q, qd, qdd):
        calls.append(len(q))
        return np.stack([qdd, np.sin(q), qd], axis=2)

    form = LinearForm(("I", "g", "b"), 2, regressor, lambda q, qd: np.zeros((len(q), 3)))
    data = generate(get_system("double_pendulum"), 50, 0)
    model = LinearParametricModel(form, [0, 2], [1.0, 0.5])
    first = model.torque_columns(data)
    again = model.with_coefficients([2.0, 0.1]).torque_columns(data)
    np.testing.assert_array_equal(first, again)
    np.testing.assert_allclose(model.predict_torque(data), data.qdd + 0.5 * data.qd)
    assert calls == [50]
    model.torque_columns(dataclasses.replace(data))  # another data set: computed for it
    assert calls == [50, 50]
