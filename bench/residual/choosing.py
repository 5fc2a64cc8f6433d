"""How the residual loop chooses a round's model (:class:`Choosing`, a part of
:class:`bench.residual.loop._Loop`): the model refitted with what the trace
accepted and the sensor's new laws, a runner-up in place of an accepted term
where refitting shows it better, and an open-ended term in place of a named
law it explains far better."""

from __future__ import annotations

import numpy as np

from bench.physics.terms import Term
from bench.residual.criteria import MIN_BIC_DROP, ROUNDOFF, bic
from bench.residual.library import label, mismatch
from bench.residual.model import LoopModel
from bench.residual.sensors import measured_rss, settle
from bench.residual.tracing import Trace


class Choosing:
    """The loop's choice of a round's model. The loop gives it its ``strategy``,
    ``train`` (the measured data as the sensor's laws correct them),
    ``measured``, ``sensor``, ``report``, ``unnamed`` (the structural findings of
    open-ended terms taken in place of named laws) and ``use`` (fit from now on
    to corrected data)."""

    def build(self, model: LoopModel, effects: list[Term], on_sensor: list[Term]):
        """``model`` refitted with ``effects`` and the sensor's new laws ``on_sensor``
        (applied exactly, :func:`~bench.residual.sensors.settle`, the laws it has
        settled again beside the new effects): the model, the sensor and the
        corrected training data."""
        proposed = self.strategy.refit(model, self.train, effects)
        if not on_sensor and not self.sensor.found_any:
            return proposed, self.sensor, self.train
        return settle(self.strategy, proposed, self.measured, self.sensor, on_sensor)

    def compare(self, model: LoopModel, effects: list[Term], on_sensor: list[Term], chosen: list[Term],
                other: list[Term], built: tuple, margin: float, weights: np.ndarray | None = None):
        """The build (:meth:`build`) with the group ``other`` in place of the accepted
        ``chosen``, where its BIC on the measured torques (each joint's rows times its
        ``weights``, as the trace weighed them), both refitted with the model,
        is lower by more than ``margin``; else ``None``. For an open-ended term far
        better than the named law accepted (:attr:`~bench.residual.tracing.Trace.mismatched`,
        margin :data:`~bench.residual.criteria.MIN_BIC_DROP`), and for the runner-up
        of a step whose model's linearisation may rank the two wrongly
        (:attr:`~bench.residual.tracing.Trace.runners_up`, margin 0)."""
        alternative = self.build(model, [t for t in effects if t not in chosen] + [t for t in other if t.place != "sensor"],
                                 [t for t in on_sensor if t not in chosen] + [t for t in other if t.place == "sensor"])
        n = self.measured.tau.size
        w = np.ones(self.measured.dof) if weights is None else weights
        floor = ROUNDOFF * float(np.mean((self.measured.tau * w) ** 2)) * n  # below it, two fits are equally exact

        def rss(m, s):
            return max(measured_rss(m, s, self.measured, w), floor)

        def size(group):  # a law's parameters, its shape among them
            return len(group) + sum(t.shape is not None for t in group[-1:])

        if bic(rss(*alternative[:2]), n, size(other)) + margin < bic(rss(*built[:2]), n, size(chosen)):
            return alternative
        return None

    def choose(self, model: LoopModel, traced: Trace, laws: dict, k: int) -> LoopModel:
        """The round's model: ``model`` refitted with what the trace accepted
        (:meth:`build`), where refitting shows it better, with a runner-up in place
        of the accepted term, and with an open-ended term in place of a named
        law it explains far better (a structural finding, :attr:`unnamed`); the
        sensor's new laws applied."""
        sensor, train, report = self.sensor, self.train, self.report
        on_sensor = [t for t in traced.accepted if t in laws]
        effects = model.effects + [t for t in traced.accepted if t not in laws]
        built = self.build(model, effects, on_sensor)
        for chosen, runner in traced.runners_up:
            other = self.compare(model, effects, on_sensor, chosen, runner, built, 0.0, traced.weights)
            if other is not None:
                report(f"  {' + '.join(map(label, runner))} instead of {' + '.join(map(label, chosen))}: "
                       f"a lower BIC once refitted with the model")
                built, effects = other, other[0].effects
                for kept, _, entry in traced.equivalents:  # the refit, not the rule, chose among them
                    if kept is chosen:
                        now_kept = " + ".join(map(label, runner))
                        entry.update(kept=now_kept, equivalent=[entry["kept"]] + [e for e in entry["equivalent"]
                                                                                  if e != now_kept],
                                     chosen_by="a lower BIC once refitted with the model, which the linearised "
                                               "comparison of the trace may rank wrongly")
                on_sensor = [t for t in on_sensor if t not in chosen] + [t for t in runner if t in laws]
        for named, rival, *seen in traced.mismatched:
            other = self.compare(model, effects, on_sensor, named, [rival], built, MIN_BIC_DROP, traced.weights)
            if other is not None:
                built, effects = other, other[0].effects
                self.unnamed[label(rival)] = mismatch(named, rival, *seen)
                report(f"round {k}: structural finding: {self.unnamed[label(rival)]['finding']}")
        proposed, new_sensor, new_train = built
        if new_sensor is not sensor:  # the sensor's laws applied exactly: the model refitted to the corrected torques
            self.use(new_train, new_sensor)
            report("  " + "; ".join(f"{e['name']} on joint(s) {e['joints']}: "
                                    + ", ".join(f"{n} = {v['value']:.5g} ± {v['stderr']:.2g}" for n, v in e["parameters"].items())
                                    for e in new_sensor.entries(train.dof)))
        return proposed
