"""The SyReNets method: one network (or several, :mod:`~methods.syrenets.multistart`)
trained within the run's budget, then its frozen function, evaluated in
float64, and its equations (:mod:`~methods.syrenets.equations`). The package
docstring describes the method and every deviation from the paper."""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from bench.core.experiment import Experiment
from bench.physics.dynamics import euler_lagrange
from bench.physics.models import NoVariant
from methods.base import METHODS
from methods.config import Named
from methods.syrenets.config import SyReNetsConfig
from methods.syrenets.equations import MAX_READABLE_TERMS, Equations
from methods.syrenets.multistart import halve
from methods.syrenets.network import SyReNet
from methods.syrenets.stacked import train_syrenets
from methods.syrenets.training import Cosine, Network, compiled_pass, inputs_of, run_steps, training_pass
from methods.torch_method import Feed, TorchLagrangianMethod, fused_adam_ok


@METHODS.add("syrenets", "neural", "symbolic", "paper")
class SyReNets(Equations, TorchLagrangianMethod):
    """SyReNets (Valle & Haddadin, 2021); see the package docstring.

    The network being trained, and what it carries between steps, is
    :attr:`net`, a :class:`~methods.syrenets.training.Network`; ``model``,
    ``frozen``, ``optimizer`` and ``scheduler`` read it.
    """

    title = "SyReNets"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("SyReNets (paper §III): 3 symbolic layers × 12 selection heads over sums, products, sines and "
               "cosines, with a shared contractive auto-encoder; reports the paper's model and two variants, "
               "`syrenets@pruned` (the fewest terms within 10 % of its MSE, as a readable equation) and "
               "`syrenets@refined` (that equation's structure with rounded inner constants, refitted by least "
               "squares)")

    stackable = True  # its own stacked loop: methods.syrenets.stacked
    Config = SyReNetsConfig
    search_space = {"layers": (2, 3), "heads": (6, 12)}
    smoke = {"layers": 2, "heads": 3, "latent": 4, "ae_hidden": 8, "head_hidden": 8, "max_steps": 10,
             "eval_samples": 128, "refine": False}
    configurations = {
        "paper": Named("the paper's text: the defaults with the contractive penalty exact, not estimated",
                       {"contractive_probes": 0}),
        "public": Named("the authors' public code: q, q̇ and q̈ as inputs, 16 worst-fitted samples replayed a step",
                        {"inputs": "q_qd_qdd", "replay": 16}),
        "best-300s": Named("the paper's indirect accuracy within 300 s on one core (results/syrenets/studies/"
                           "syrenets_300s_compiled_best): float32, replay, four starts, cosine schedule, compiled",
                           {"replay": 16, "dtype": "float32", "starts": 4, "lr_schedule": "cosine", "compile": True}),
    }
    net: Network | None = None

    # -- the network in place -------------------------------------------------------
    @property
    def model(self) -> SyReNet:
        return self.net.model

    @property
    def frozen(self) -> list[torch.Tensor]:
        return self.net.frozen

    @frozen.setter
    def frozen(self, weights: list[torch.Tensor]) -> None:
        self.net.frozen = weights

    @property
    def optimizer(self) -> torch.optim.Optimizer:
        return self.net.optimizer

    @property
    def scheduler(self):
        return self.net.scheduler

    def _inputs(self, q, qd, qdd=None):
        return inputs_of(q, qd, qdd, self.config.inputs)

    def build_model(self, train, seed: int | None = None):
        """A network for ``train``'s shape, initialised from ``seed`` (the fit's by default)."""
        n_x = train.dof * (2 if self.config.inputs == "q_qd" else 3)
        torch.manual_seed(self.seed if seed is None else seed)
        return SyReNet(n_x, self.config)

    def _network(self, train, start: int = 0) -> Network:
        """A new network with its optimiser (the scale ``S`` at ``C`` times the
        learning rate) and schedule; ``start`` k > 0 initialises the k-th
        network of a multi-start fit from its own seed. Its frozen weights
        come from the first batch, before its first step."""
        cfg = self.config
        seed = self.seed if start == 0 else int(np.random.SeedSequence([self.seed, start]).generate_state(1)[0])
        model = self.build_model(train, seed).to(self.device, self.dtype)
        C = model.C
        scale_params = list(model.S.parameters())
        other = [p for n, p in model.named_parameters() if not n.startswith("S.")]
        optimizer = torch.optim.Adam(
            [{"params": other, "lr": cfg.lr}, {"params": scale_params, "lr": cfg.lr * C}],
            betas=cfg.betas, **({"fused": True} if fused_adam_ok(self.dtype, self.device) else {}),
        )
        if cfg.lr_schedule == "plateau":
            scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
                optimizer, mode="min", factor=cfg.lr_factor, patience=cfg.lr_patience, min_lr=[cfg.lr_min, cfg.lr_min * C]
            )
        else:
            scheduler = Cosine(optimizer, [cfg.lr_min, cfg.lr_min * C])
        return Network(model, optimizer, scheduler, frozen=[])

    def _setup(self, train, start: int = 0) -> None:
        """Put a new network (:meth:`_network`) in place."""
        self.net = self._network(train, start)

    def train_step(self, batch: dict[str, torch.Tensor], experiment: str) -> torch.Tensor:
        """One optimisation step of the network in place on ``batch``; returns each sample's squared error."""
        loss, err, weights = self._pass(batch, experiment)
        self.net.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.finish_step(err, weights)
        return err

    def finish_step(self, err: torch.Tensor, weights: list[torch.Tensor]) -> None:
        """The step of the network in place after its gradients are in: the
        optimiser's, the schedule's (on the batch's error ``err``) and the
        frozen ``weights`` the batch selected."""
        net = self.net
        net.optimizer.step()
        batch_loss, a = err.mean().item(), self.config.lr_smoothing
        net.watched = batch_loss if net.watched is None or not a else a * net.watched + (1 - a) * batch_loss
        net.scheduler.step(net.watched)
        net.frozen = weights

    def _pass(self, batch: dict[str, torch.Tensor], experiment: str):
        """:func:`~methods.syrenets.training.training_pass` of the network in place, compiled with ``compile``."""
        cfg = self.config
        experiment = Experiment.of(experiment)
        return (compiled_pass() if cfg.compile else training_pass)(
            self.model, batch["q"], batch["qd"], batch["qdd"], batch[experiment.target], experiment.learns_torque,
            cfg.inputs, cfg.compile)

    def stacking_unavailable_reason(self) -> str | None:
        if self.config.compile:
            return "syrenets with compile=True trains alone: its compiled pass is one network's"
        return None

    @classmethod
    def train_stacked(cls, methods, starts, datasets, experiment, slots) -> None:
        train_syrenets(methods, starts, datasets, experiment, slots)

    # -- the fit --------------------------------------------------------------------
    def _fit(self, train, experiment, progress):
        run_steps(self.steps(train, experiment, progress), lambda batch: self.train_step(batch, experiment))

    def steps(self, train, experiment, progress):
        """The fit's loop as a generator: it yields each step's batch, for the
        network in place (:attr:`net`), and is sent back each sample's
        squared error once the step is done, or ``None`` where the step was
        not done and the loop must end (:func:`~methods.syrenets.training.run_steps`;
        a stacked fit, :mod:`methods.syrenets.stacked`, does the steps of
        several seeds' loops at once)."""
        cfg = self.config
        self._start_training()
        t = train.tensors(self.dtype, self.device)
        n, bs = len(train), min(cfg.batch_size, len(train))
        feed = Feed.start(n, bs, self.seed)
        progress.reserve(cfg.post_fraction * progress.remaining())
        self._starts = None
        if self.warm_start:  # continue the network, its optimiser and its frozen weights
            self.frozen = [w.to(self.device, self.dtype) for w in self.frozen]
            self.net.lr_drops, self.net.replay = [], torch.empty(0, dtype=torch.long)
            if isinstance(self.scheduler, Cosine):
                self.scheduler.start(progress)
            yield from self._train(t, experiment, progress, feed)
            return
        networks = []
        for k in range(cfg.starts):
            net = self._network(train, k)
            with torch.no_grad():
                net.frozen = [w.detach() for w in net.model.select(self._inputs(t["q"][:bs], t["qd"][:bs], t["qdd"][:bs]))[1]]
            if isinstance(net.scheduler, Cosine):
                net.scheduler.start(progress)
            networks.append(net)
        self.net = networks[0]
        if cfg.starts > 1:
            self._starts = yield from halve(self, networks, t, experiment, progress, feed)
        del networks
        if progress.stop_reason is None:
            yield from self._train(t, experiment, progress, feed)

    def _prepare(self, train, experiment) -> None:
        """With ``compile``, compile the training pass for the loop's batch
        sizes (with and without the replayed samples) on a network of the
        fit's shapes, before the budget starts: the compiled pass takes the
        network as an argument, so the fit's networks reuse it. A fresh
        machine (an empty compile cache) then leaves a run the same learning
        time as a warm one. The gradients are discarded; the time it took is
        the record's ``details.compile_seconds``."""
        self._compile_seconds = None
        if not self.config.compile:
            return
        start = time.perf_counter()
        cfg, dtype, device = self.config, getattr(torch, self.config.dtype), torch.device(self.train_device)
        with torch.random.fork_rng():
            torch.manual_seed(0)
            model = SyReNet(train.dof * (2 if cfg.inputs == "q_qd" else 3), cfg).to(device, dtype)
            t = train.tensors(dtype, device)
            bs = min(cfg.batch_size, len(train))
            for size in sorted({bs, bs + cfg.replay}):
                idx = torch.arange(size) % len(train)
                b = {k: v[idx] for k, v in t.items()}
                compiled_pass()(model, b["q"], b["qd"], b["qdd"], b[experiment.target], experiment.learns_torque,
                                cfg.inputs, True)[0].backward()
        self._compile_seconds = round(time.perf_counter() - start, 2)

    def _train(self, t, experiment, progress, feed: Feed, until: float = math.inf) -> bool:
        """Steps of the network in place until ``progress.fraction()`` reaches
        ``until`` (a generator, as :meth:`steps`); ``False`` once the budget is spent."""
        cfg, net = self.config, self.net
        lr = net.optimizer.param_groups[0]["lr"]
        while progress.fraction() < until:
            if not progress.step():
                return False
            idx = torch.cat([feed.next(), net.replay])
            err = yield {k: v[idx] for k, v in t.items()}
            if err is None:
                return False
            if cfg.lr_schedule == "plateau" and net.optimizer.param_groups[0]["lr"] != lr:
                lr = net.optimizer.param_groups[0]["lr"]
                net.lr_drops.append([progress.steps + 1, round(progress.elapsed(), 2), lr])
            if cfg.replay:
                net.replay = idx[torch.argsort(err, descending=True)[: cfg.replay].cpu()]  # the feed's indices are the CPU's
        return True

    def _get_state(self):
        return {"model": {k: v.detach().clone() for k, v in self.model.state_dict().items()},
                "frozen": [w.clone() for w in self.frozen]}

    def _set_state(self, state):
        self.model.load_state_dict(state["model"])
        self.frozen = [w.clone() for w in state["frozen"]]

    def _frozen_lagrangian(self, qdd=None):
        def lag(q, qd):
            return self.model.evaluate(self._inputs(q, qd, qdd), self.frozen)
        return lag

    def predict_lagrangian(self, data):
        t = data.tensors(self.dtype, self.device)
        with torch.no_grad():
            out = self.model.evaluate(self._inputs(t["q"], t["qd"], t["qdd"]), self.frozen)
        return out.double().cpu().numpy()

    def saved(self, packer):
        """Not yet: its fit is a network with frozen parts and a refined equation beside it."""
        raise ValueError("a SyReNets fit (its network, with its frozen parts) cannot be saved to a model file yet")

    def predict_torque(self, data):
        if self.config.inputs == "q_qd":
            return super().predict_torque(data)
        # qdd is an input too: each chunk's Lagrangian sees its own accelerations
        t = data.tensors(self.dtype, self.device)
        taus = []
        for sl in range(0, len(data), 8192):
            part = slice(sl, sl + 8192)
            taus.append(euler_lagrange(self._frozen_lagrangian(t["qdd"][part]), t["q"][part], t["qd"][part], t["qdd"][part]))
        return torch.cat(taus).double().cpu().numpy()

    def lagrangian(self, q, qd):
        return self._frozen_lagrangian()(q, qd)

    def not_a_lagrangian(self):
        if self.config.inputs == "q_qd":
            return None
        return ("inputs='q_qd_qdd' feeds qdd into L (the public code's choice), so its torques are not affine in "
                "qdd: no exact recovery or rollout")

    def _with_weights(self, weights, fn, *args):
        saved, self.frozen = self.frozen, weights
        try:
            return fn(*args)
        finally:
            self.frozen = saved

    # -- evaluation, pruning and refinement ----------------------------------------------
    def _post_fit(self, train, experiment, seconds_left):
        deadline = time.perf_counter() + seconds_left
        super()._post_fit(train, experiment, seconds_left)  # float64 from here on, for pruning and refinement
        self.frozen = [w.to("cpu", torch.float64) for w in self.frozen]
        self._variants, self._notes = {}, {}
        rng = np.random.default_rng(self.seed)
        ref = train.subset(np.sort(rng.choice(len(train), min(len(train), 1024), replace=False)))
        self._pruned = self._prune(ref, experiment)
        self._variants["pruned"] = self._pruned
        if not self.config.refine:
            return
        if self.config.inputs != "q_qd":
            refined = NoVariant("refinement needs inputs='q_qd' (a Lagrangian of q and qd)", "not_applicable")
        else:
            refined = self._refine(train, experiment, deadline)
        self._variants["refined"] = refined
        if isinstance(refined, NoVariant):
            self._notes["refined"] = refined.reason

    def record_details(self):
        notes = dict(getattr(self, "_notes", {}))
        if self.config.lr_schedule == "plateau" and getattr(self, "net", None) is not None:
            # [step, seconds into the fit, new learning rate] for each cut of the plateau schedule
            notes["lr_drops"] = self.net.lr_drops
        if getattr(self, "_starts", None):
            # the multi-start fit: each round's [network, its lowest training MSE so far], and the network kept
            notes["starts"] = self._starts
        if getattr(self, "_compile_seconds", None) is not None:
            notes["compile_seconds"] = self._compile_seconds
        if notes.get("pruned_terms", 0) > MAX_READABLE_TERMS:
            notes["expression_omitted"] = f"the pruned equation keeps {notes['pruned_terms']} terms (> {MAX_READABLE_TERMS})"
        return notes
