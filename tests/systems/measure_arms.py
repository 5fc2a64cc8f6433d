"""Prints the figures that tests/systems/test_urdf.py and the Panda test of
tests/residual/test_loop.py bound: bench data and the suite's Euler-Lagrange
transform against Pinocchio's RNEA, SysId's base parameters on the Panda, and the
residual loop on the Panda with friction on every joint. Run from the
repository root: python tests/systems/measure_arms.py"""
import numpy as np, torch, sys
sys.path.insert(0, ".")
from tests.systems.test_urdf import pin, pinocchio_panda, pinocchio_pendulum
from bench.core.data import generate, mse
from bench.physics.dynamics import euler_lagrange
from bench.physics.undeclared import add_effects
from bench.residual import residual_loop
from methods import METHODS
from systems import get_system
from systems.n_link_pendulum import n_link_pendulum
from bench.core.budget import Budget
# bench data vs RNEA on the Panda
panda = get_system("panda"); data = generate(panda, 300, 3, cache=False)
model = pinocchio_panda(); d = model.createData()
tau = np.stack([pin.rnea(model, d, q, v, a) for q, v, a in zip(data.q, data.qd, data.qdd)])
print("panda |data - rnea| max", np.abs(tau - data.tau).max())
# EL vs RNEA, n = 1..7
worst = 0; top = 0
for n in range(1, 8):
    masses, lengths = np.linspace(0.7, 1.9, n), np.linspace(1.3, 0.6, n)
    cls = n_link_pendulum(n); params = {**{f"m{i+1}": m for i, m in enumerate(masses)}, **{f"l{i+1}": x for i, x in enumerate(lengths)}, "g": 9.81}
    system = cls(cls.Params(**params)); rng = np.random.default_rng(n)
    q, qd, qdd = (rng.uniform(-1.5, 1.5, (200, n)) for _ in range(3))
    ours = euler_lagrange(system.lagrangian, *(torch.from_numpy(x) for x in (q, qd, qdd))).numpy()
    A = np.tril(np.ones((n, n))); Ai = np.linalg.inv(A); m = pinocchio_pendulum(n, masses, lengths, 9.81); dd = m.createData()
    theirs = np.stack([pin.rnea(m, dd, Ai @ a, Ai @ b, Ai @ c) for a, b, c in zip(q, qd, qdd)]) @ Ai
    worst = max(worst, np.abs(ours - theirs).max()); top = max(top, np.abs(theirs).max())
print("EL vs RNEA n=1..7 max diff", worst, "max |tau|", top)
train, test = generate(panda, 4000, 0), generate(panda, 1000, 1000)
s = METHODS["sysid"]().fit(train, "indirect", 0, Budget(seconds=60.0)); f = s.record_details()
print("panda sysid", f["base_parameters"], "param error", f["parameter_error"], "test mse", mse(s.predict_torque(test), test.tau))
fx = {"viscous_friction": tuple(0.1 + 0.05 * j for j in range(7)), "coulomb_friction": tuple(0.3 + 0.1 * j for j in range(7))}
tr, te = add_effects(generate(panda, 1000, 0), fx), add_effects(generate(panda, 500, 1000), fx)
out = residual_loop("sysid", tr, te, budget=Budget(seconds=20), report=lambda l: None)
print("panda loop", len(out.effects), out.mse_before["test"], out.mse_after["test"])
