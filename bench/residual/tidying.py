"""What follows a round's joint refit in the residual loop
(:class:`Tidying`, a part of :class:`bench.residual.loop._Loop`): redundant
effects and sensor laws dropped, shapes refined, each law its simplest and
possible, and what the data do not identify, or held-out data do
not confirm, dropped with its finding."""

from __future__ import annotations

from bench.residual.beyond_data import beyond_data, earns_place, finding, not_identified
from bench.residual.library import label, structural
from bench.residual.model import LoopModel
from bench.residual.pruning import drop_inadmissible, prune, refine_shapes, simplest_laws
from bench.residual.criteria import MIN_BIC_DROP
from bench.residual.sensors import confine as confine_sensor, inadmissible as inadmissible_sensor, redundant


class Tidying:
    """The loop's steps after a joint refit. The loop gives them its
    ``strategy``, ``train`` (the measured data as the sensor's laws correct
    them), ``measured``, ``sensor``, ``report``, ``beyond`` (the findings of
    effects dropped for claiming beyond the data), ``timed`` (statistics'
    time), ``in_budget`` (a stage's check of the time budget), ``heldout``
    and ``use`` (fit from now on to corrected data)."""

    def tidy(self, proposed: LoopModel, findings: dict):
        """What follows a round's joint refit: redundant effects and sensor laws
        dropped, shapes refined, each law its simplest and possible, and what the
        data do not identify or held-out data do not confirm dropped
        (findings go to ``findings`` and :attr:`beyond`). Returns the model, the
        labels removed and the laws simplified."""
        strategy, report = self.strategy, self.report
        proposed, removed = self.timed(prune, strategy, proposed, self.train, report)
        self.in_budget("dropping redundant effects")
        if self.sensor.found_any:
            proposed, new_sensor, impossible = self.timed(inadmissible_sensor, strategy, proposed, self.measured,
                                                          self.sensor)
            for term, entry in impossible:
                findings[label(term)] = entry
                report(f"  dropping {label(term)}: {entry['finding']}")
            if impossible:
                self.use(new_sensor.correct(self.measured), new_sensor)
                removed += [label(term) for term, _ in impossible]
        if self.sensor.found_any:
            proposed, new_sensor, new_train, gone = self.timed(redundant, strategy, proposed, self.measured,
                                                               self.sensor, MIN_BIC_DROP)
            for text in gone:
                report(f"  dropping {text}: redundant after the joint refit")
            if gone:
                self.use(new_train, new_sensor)
            removed += gone
        proposed = refine_shapes(strategy, proposed, self.train, report)
        self.in_budget("refining the laws' shapes")
        proposed, simplified, impossible = self.timed(self.settle, proposed)
        self.in_budget("simplifying the laws")
        for term, c, se in impossible:
            findings[label(term)] = structural(term, c, se)
            removed.append(label(term))
        proposed, beyond = self.timed(self.confine, proposed)
        self.in_budget("checking what the data identify")
        if self.sensor.found_any:
            proposed, new_sensor, new_train, gone = self.timed(
                confine_sensor, strategy, proposed, self.measured, self.sensor, self.heldout)
            for term, entry in gone:
                self.beyond[label(term)] = (term, entry)
                report(f"  dropping {label(term)}: a law of the sensor that held-out data do not confirm")
                beyond.append(label(term))
            if gone:
                self.use(new_train, new_sensor)
        removed += beyond
        if beyond:  # a refit without what was dropped can leave a law impossible or not itself again
            proposed, more, impossible = self.timed(self.settle, proposed)
            simplified += more
            for term, c, se in impossible:
                findings[label(term)] = structural(term, c, se)
                removed.append(label(term))
        return proposed, removed, simplified

    def settle(self, model: LoopModel):
        """Each law its simplest (:func:`~bench.residual.pruning.simplest_laws`), then
        no impossible coefficient (:func:`~bench.residual.pruning.drop_inadmissible`),
        again until neither changes anything: dropping a law's impossible part can
        leave a law that is not itself (a Stribeck hump without its Coulomb level).
        Returns the model, the replacements and the dropped ``(term, coefficient, stderr)``."""
        simplified, impossible = [], []
        while True:
            model, more = simplest_laws(self.strategy, model, self.train, self.report)
            simplified += more
            model, dropped = drop_inadmissible(self.strategy, model, self.train, self.report)
            impossible += dropped
            if not dropped:
                return model, simplified, impossible

    def confine(self, model: LoopModel):
        """``model`` without each effect the data do not identify, and each that
        claims beyond the training data and does not earn its place on a
        held-out trajectory (:mod:`bench.residual.beyond_data`), dropped one at a time
        with a refit; returns the model and the labels dropped (their findings
        go to :attr:`beyond`)."""
        dropped = []
        while True:
            suspects = [(i, why, None) for i, why in not_identified(model)] + \
                [(i, why, self.strategy) for i, why in beyond_data(model, self.train)]
            for index, why, strategy in suspects:
                keep, verdict = (False, "") if strategy is None else earns_place(strategy, model, self.train, index)
                if keep:
                    continue
                term = model.effects[index]
                self.beyond[label(term)] = (term, finding(term, model.coef[index], model.stderr[index], why, verdict))
                self.report(f"  dropping {label(term)}: {why}; {verdict}")
                model = self.strategy.refit(model, self.train, [t for t in model.effects if t is not term])
                dropped.append(label(term))
                break
            else:
                return model, dropped
