"""What the commands share: the
options several of them take (``--set``, ``--plugin``, ``--budget`` with
``--steps``), with what the commands do with them.

The option values' types (seeds, counts, fractions, ``NAME=VALUE``) are in
:mod:`bench.core.arguments`, shared with the measurement scripts.

The registries of methods and systems are imported in the functions that
need them, so that a command that refuses its input before it
names a method or builds a system has not imported the methods (torch) or
the physics (sympy, Pinocchio).
"""

from __future__ import annotations

import re
from pathlib import Path

from bench.core.arguments import assignment, positive, positive_int
from bench.core.budget import DEFAULT_BUDGET_S
from bench.core.experiment import Experiment
from bench.core.devices import CHOICES, resolve as resolve_device
from bench.core.registry import RegistryError, UnknownName
from bench.cli.parser import UsageError
from bench.runner.plugins import import_plugins, system_plugins

STEPS_HELP = ("bound each run by N steps of its method's work (gradient steps, GP generations, solves) instead of by "
              "time: the run is then a pure function of its seed and gives the same numbers on any machine")
PLUGIN_HELP = "a .py file or module that registers extra methods or systems (repeatable)"


def add_set(parser, what: str = "the method") -> None:
    """``--set NAME=VALUE`` and ``--set METHOD.NAME=VALUE``, repeatable."""
    parser.add_argument("--set", dest="overrides", type=assignment, action="append", default=[],
                        metavar="[METHOD.]NAME=VALUE",
                        help=f"a hyperparameter of {what}, e.g. hidden=64; METHOD.NAME=VALUE sets it for that method "
                             "only, e.g. mlp.hidden=64 (repeatable)")


def add_tune(parser, what: str = "each run") -> None:
    """``--tune``: choose the method's hyperparameters on the training data (:mod:`bench.evaluation.tuning`)."""
    parser.add_argument("--tune", action="store_true",
                        help=f"{what} chooses its method's hyperparameters from the method's search space (python -m "
                             "bench list shows it) by validation on the training data alone (whole trajectories, or "
                             "spans in time of one), within its budget: the final fit has half of a time budget, the "
                             "search the rest; under --steps every fit does the steps. The record keeps every "
                             "combination's validation MSE; tables show the tuned runs beside the others")


def add_config(parser, what: str = "the method") -> None:
    """``--config NAME`` and ``--config METHOD=NAME``, repeatable, with ``--smoke`` for ``--config smoke``."""
    parser.add_argument("--config", dest="configs", action="append", default=[], metavar="[METHOD=]NAME",
                        help=f"a named configuration of {what} (python -m bench list names them), e.g. paper; "
                             "METHOD=NAME picks it for that method only, e.g. syrenets=best-300s; --set applies on "
                             "top of it (repeatable)")
    parser.add_argument("--smoke", action="store_true", help=f"the tiny smoke configuration of {what} (--config smoke)")


def configurations(args, methods: list[str]) -> dict[str, str]:
    """Each method's configuration by name from ``--smoke`` and ``--config``:
    ``default`` (or ``smoke``), then every ``NAME`` given alone for the
    methods that offer it, then every ``METHOD=NAME``, which wins. A name
    that none of ``methods`` offers, or that its method does not, is an error."""
    from methods import METHODS

    chosen = {m: "smoke" if args.smoke else "default" for m in methods}
    given = [(method.strip(), name.strip()) for method, _, name in (c.rpartition("=") for c in args.configs)]
    for method, name in sorted(given, key=lambda g: bool(g[0])):  # a method's own choice last
        if method and method not in methods:
            raise UsageError(f"--config {method}={name}: {method!r} is not a method of this command "
                             f"(methods: {', '.join(methods)})")
        targets = [method] if method else [m for m in methods if name in METHODS[m].configuration_names()]
        if not targets:
            offered = sorted({n for m in methods for n in METHODS[m].configuration_names()})
            raise UsageError(f"--config {name}: no method of this command offers it (they offer {', '.join(offered)})")
        for m in targets:
            if name not in METHODS[m].configuration_names():
                raise UsageError(f"--config {method}={name}: {m} offers {', '.join(METHODS[m].configuration_names())}")
            chosen[m] = name
    return chosen


def add_split(parser) -> None:
    """``--split NAME``: which train and test split of a measured system's trajectories."""
    parser.add_argument("--split", default=None, metavar="NAME",
                        help="a measured system's split of its trajectories into train and test: default, or swapped "
                             "(train on the default's test trajectories and test on its training ones)")


def check_split(split: str | None, systems: list[str]) -> None:
    """Every system offers ``split`` (``None``: each its default)."""
    from systems import SYSTEMS

    if split is None:
        return
    lacking = [s for s in systems if split not in SYSTEMS[s].splits]
    if lacking:
        raise UsageError(f"--split {split}: {', '.join(lacking)} offer(s) only {', '.join(SYSTEMS[lacking[0]].splits)}")


def add_plugin(parser) -> None:
    parser.add_argument("--plugin", action="append", default=[], help=PLUGIN_HELP)


def add_ignore_limits(parser, what: str = "fit --train/--test files whose positions") -> None:
    parser.add_argument("--ignore-limits", action="store_true",
                        help=f"{what} leave the arm's joint limits (by default one line names the file, the joint, "
                             f"the range seen and the limits, and nothing is fitted)")


def add_device(parser, default: str | None = "cpu") -> None:
    """``--device cpu|cuda|auto``: where the torch methods train."""
    parser.add_argument("--device", choices=CHOICES, default=default,
                        help="where the torch methods (SyReNets, the MLP, DeLaN, SysId's network, a torch plugin) "
                             "train: cpu, cuda, or auto (cuda where torch sees one); evaluation stays on the CPU in "
                             "float64; other methods ignore it"
                             + (f" (default {default})" if default else " (default: the recorded run's)"))


def device(name: str, methods: list[str]) -> str:
    """``--device`` resolved to ``cpu`` or ``cuda`` (:func:`bench.core.devices.resolve`,
    a one-line error where cuda is asked for and there is none), saying once
    which of ``methods`` do not train on it."""
    resolved = resolve_device(name)
    if resolved != "cpu":
        from methods import METHODS

        ignoring = [m for m in methods if m in METHODS and not METHODS[m].uses_device]
        if ignoring:
            print(f"--device {name}: {', '.join(ignoring)} {'is not a torch method' if len(ignoring) == 1 else 'are not torch methods'} "
                  f"and run{'s' if len(ignoring) == 1 else ''} on the CPU")
    return resolved


def add_budget(parser, what: str, default: float = DEFAULT_BUDGET_S) -> None:
    """``--budget SECONDS`` and ``--steps N``, for ``what`` ("per run", "for the fit"); ``default`` seconds
    where neither is given."""
    parser.set_defaults(default_budget_s=default)
    parser.add_argument("--budget", type=positive, default=None,
                        help=f"wall-clock seconds {what} (default {default:g}); with --steps, a ceiling past "
                             "which a run is killed and recorded as timeout (default: none)")
    parser.add_argument("--steps", type=positive_int, default=None, help=STEPS_HELP)


def budget(args) -> tuple[float | None, int | None]:
    """``(budget_s, steps)`` from ``--budget`` and ``--steps``: seconds
    (default: :func:`add_budget`'s, :data:`DEFAULT_BUDGET_S` unless the command
    says otherwise), or steps with an optional ceiling."""
    if args.steps is None:
        return (args.budget if args.budget is not None else getattr(args, "default_budget_s", DEFAULT_BUDGET_S)), None
    return args.budget, args.steps


def resampled(given) -> list[str]:
    """A line for each recording of ``given`` (``(train, test)`` or ``None``) put on a uniform grid, as
    :func:`bench.core.recordings.resampling` words it: ``train: recording NAME: resampled from ...``."""
    return [f"{name}: recording {recording}: {words}" for name, part in zip(("train", "test"), given or ())
            if part is not None for recording, words in (part.meta or {}).get("resampled", {}).items()]


def number(x: float | None, spec: str = ".4g") -> str:
    """A figure as a command prints it; ``n/a`` where there is none (no test data)."""
    return "n/a" if x is None else format(x, spec)


def hyperparameters(overrides: list[tuple[str, object]], method: str, methods: list[str]) -> dict:
    """The ``--set`` values for ``method`` among the command's ``methods``:
    every ``NAME=VALUE``, then every ``METHOD.NAME=VALUE`` of this method,
    which wins. A ``METHOD.`` that names none of ``methods`` is an error."""
    common, own = {}, {}
    for key, value in overrides:
        target, dot, name = key.rpartition(".")
        if not dot:
            common[key] = value
            continue
        if target not in methods:
            raise UsageError(f"--set {key}: {target!r} is not a method of this command "
                             f"(methods: {', '.join(methods)})")
        if target == method:
            own[name] = value
    return {**common, **own}


def load_plugins(args, systems: list[str] = (), methods: list[str] = ()) -> tuple[list[str], tuple[str, ...]]:
    """Import ``--plugin`` files and register any ``urdf:PATH`` system; returns
    the systems' names and the plugins a run's own process needs."""
    import_plugins(args.plugin)
    names, arms = system_plugins(systems)
    return names, plugin_paths(args.plugin) + arms


def plugin_paths(plugins: list[str]) -> tuple[str, ...]:
    """Plugin files as absolute paths (runs import them in their own processes); module names as given."""
    return tuple(str(Path(p).resolve()) if p.endswith(".py") else p for p in plugins)


def check_names(args, systems=(), methods=(), experiments=(), named: bool = True,
                built: dict | None = None) -> dict[tuple[str, str], str]:
    """Every name known; an unknown one that a ``.py`` file in the working
    folder registers, while no ``--plugin`` gave it, says so.

    A method the user ``named`` that applies to none of ``systems``
    (:meth:`~methods.base.Method.refused_on`) is refused in one line. One they
    did not name (every registered method, the default of ``run``) is not: the
    matrix records its runs as not applicable. Returns why each such
    ``(method, system)`` pair does not apply. ``built``: the systems the
    command has built already, by name (the others are built here, once)."""
    from methods import METHODS
    from systems import SYSTEMS

    for registry, names in ((SYSTEMS, systems), (METHODS, methods)):
        for name in names:
            try:
                registry.entry(name)
            except UnknownName as exc:  # a name a plugin might register: say which file in the folder names it
                raise UsageError(f"{exc}{_plugin_hint(exc.name, args.plugin)}") from None
            except RegistryError as exc:
                raise UsageError(str(exc)) from None
    for name in experiments:
        Experiment.of(name)
    skipped = {}
    built = {s: (built or {}).get(s) or SYSTEMS[s]() for s in systems} if methods else {}  # each once
    for method in methods:
        refused = {s: METHODS[method].refused_on(built[s]) for s in systems}
        reason = next((r for r in refused.values() if r), None)
        if named and reason and all(refused.values()):  # on none of the systems given
            raise UsageError(reason)
        skipped.update({(method, s): r for s, r in refused.items() if r})
    return skipped


def _plugin_hint(name: str, plugins: list[str]) -> str:
    quoted = re.compile(rf"""["']{re.escape(name)}["']""")
    given = {Path(p).resolve() for p in plugins if p.endswith(".py")}
    for path in sorted(Path.cwd().glob("*.py")):
        try:
            if path.resolve() not in given and quoted.search(path.read_text(errors="replace")):
                return f"; {path.name} names it: add --plugin {path.name}"
        except OSError:
            continue
    return "; one from your own file needs --plugin FILE.py" if not plugins else ""
