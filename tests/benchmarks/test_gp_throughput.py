"""Fitness evaluation throughput of genetic programming, in evaluations per
second (trees x samples per second), on the same random genes and data.

* ``direct-jets``: tree values (the direct experiment's fitness columns);
* ``indirect-jets``: tree values with their Euler–Lagrange images, by the
  second-order forward-mode evaluator of :mod:`methods.jets` (what MGGP uses);
* ``indirect-autograd``: the same images by the suite's autograd transform,
  one compiled torch function per tree (the alternative MGGP could use);
* ``direct-pyoperon``: Operon's C++ evaluator (float32) on the same trees.

Run with ``make benchmark``.
"""

from __future__ import annotations

import random

import numpy as np
import pytest
import torch

from bench.core.data import generate
from bench.physics.dynamics import euler_lagrange
from bench.core import symbolic
from methods import METHODS
from methods.jets import JetAlgebra
from systems import get_system

pytestmark = pytest.mark.benchmark

N_TREES, N_SAMPLES = 200, 1024


@pytest.fixture(scope="module")
def setup():
    data = generate(get_system("double_pendulum"), N_SAMPLES, 0)
    m = METHODS["mggp"]()
    m.experiment, m.dof = "indirect", 2
    m.pset = m._primitive_set(2)
    random.seed(0)
    genes = [m._new_gene() for _ in range(N_TREES)]
    return m, data, genes


def _record(benchmark, name):
    benchmark.extra_info["evaluations_per_s"] = N_TREES * N_SAMPLES / benchmark.stats.stats.mean
    benchmark.extra_info["label"] = name


def test_direct_jets(benchmark, setup):
    m, data, genes = setup
    benchmark.group = "gp-fitness-evaluation"
    algebra = JetAlgebra(data.q, data.qd, data.qdd, order=0)
    with np.errstate(all="ignore"):
        benchmark.pedantic(lambda: [m._evaluate_tree(g, algebra).v for g in genes], rounds=5, iterations=1)
    _record(benchmark, "direct, numpy")


def test_indirect_jets(benchmark, setup):
    m, data, genes = setup
    benchmark.group = "gp-fitness-evaluation"
    algebra = JetAlgebra(data.q, data.qd, data.qdd, order=2)
    with np.errstate(all="ignore"):
        benchmark.pedantic(lambda: [algebra.torque(m._evaluate_tree(g, algebra)) for g in genes], rounds=5, iterations=1)
    _record(benchmark, "indirect, numpy jets")


def test_indirect_autograd(benchmark, setup):
    m, data, genes = setup
    benchmark.group = "gp-fitness-evaluation"
    torch.set_num_threads(1)
    t = data.tensors()

    def run():
        for g in genes:
            f = symbolic.to_torch(m._gene_sympy(g), 2)
            euler_lagrange(f, t["q"], t["qd"], t["qdd"])

    benchmark.pedantic(run, rounds=2, iterations=1)
    _record(benchmark, "indirect, sympy->torch autograd")


def _operon_infix(gene, variable_index) -> str:
    """A DEAP gene as Operon infix text over X1..X4."""
    names = {alias: f"X{k + 1}" for alias, k in variable_index.items()}
    stack = []
    for node in reversed(gene):
        if node.arity == 0:
            v = node.value
            stack.append(names[v] if isinstance(v, str) else f"({v!r})")
            continue
        args = [stack.pop() for _ in range(node.arity)]
        if node.name in ("add", "sub", "mul"):
            op = {"add": "+", "sub": "-", "mul": "*"}[node.name]
            stack.append(f"({args[0]} {op} {args[1]})")
        elif node.name == "sqrt":
            stack.append(f"sqrt(abs({args[0]}))")
        elif node.name == "cube":
            stack.append(f"({args[0]} ^ 3)")
        else:
            stack.append(f"{node.name}({args[0]})")
    return stack[0]


def test_direct_pyoperon(benchmark, setup):
    op = pytest.importorskip("pyoperon")
    m, data, genes = setup
    benchmark.group = "gp-fitness-evaluation"
    X = np.asfortranarray(np.concatenate([data.q, data.qd], axis=1))
    ds = op.Dataset(X)
    hashes = {v.Name: v.Hash for v in ds.Variables}
    trees = [op.InfixParser.Parse(_operon_infix(g, m.variable_index), hashes) for g in genes]
    rows = op.Range(0, N_SAMPLES)
    # check that Operon computes the same values as the suite
    algebra = JetAlgebra(data.q, data.qd, data.qdd, order=0)
    with np.errstate(all="ignore"):
        ours = np.stack([m._evaluate_tree(g, algebra).v for g in genes[:20]])
    theirs = np.stack([op.Evaluate(t, ds, rows) for t in trees[:20]]).astype(np.float64)
    finite = np.isfinite(ours) & np.isfinite(theirs)
    assert np.allclose(ours[finite], theirs[finite], rtol=1e-3, atol=1e-3 * np.abs(ours[finite]).max())
    benchmark.pedantic(lambda: [op.Evaluate(t, ds, rows) for t in trees], rounds=5, iterations=1)
    _record(benchmark, "direct, pyoperon (C++, float32)")
