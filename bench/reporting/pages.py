"""Blocks of a page generated from the records: a published page's tables and
lists that are not a run folder's ``tables.md``.

Wherever a page under results/ (or the README) holds::

    <!-- generated NAME -->
    ...
    <!-- /generated -->

the lines between the marks are what the generator registered as ``NAME``
(:func:`block`) makes from the records under results/ (the generators live in
one module per page, which :mod:`bench.reporting.index` imports); ``python -m bench
index`` rewrites them (:func:`rewrite`) beside the pages' marked figures, and
:func:`stale_blocks` lists those that disagree with their records. A page's
prose carries single numbers as marked figures instead
(:mod:`bench.reporting.index`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

from bench.core.errors import UserError
from bench.core.experiment import INDIRECT
from bench.runner.records import Record, read_records
from methods import METHODS

BLOCK = re.compile(r"(?P<open><!-- generated (?P<name>[\w.-]+) -->\n)(?P<body>.*?)(?P<close><!-- /generated -->)", re.S)

#: the generators: ``name -> f(results root) -> markdown``
GENERATORS: dict[str, Callable[[Path], str]] = {}


def figure(x: float) -> str:
    """A figure in a generated block: three significant digits."""
    return f"{x:.3g}"


def learners(present, labels=()) -> list[tuple[str, str]]:
    """The learners a page lists: every method of ``present`` (those its records hold), each once, those of
    ``labels`` (``(method, label)`` pairs: the page's order and its own words, such as the configuration it
    ran) first, in that order, then the others in name order under their registered names on the pages
    (:meth:`methods.base.Method.display_name`; a hybrid's from its prior's and its residual's), so that a new
    learner's records put it on the page without the page naming it."""
    present = set(present)
    named = [(m, label) for m, label in labels if m in present]
    known = {m for m, _ in named}
    others = sorted(present - known)
    return named + [(m, METHODS[m].display_name() if m in METHODS else m) for m in others]


def indirect_records(root: Path, folder: str, tuned: bool | None = False) -> list[Record]:
    """The indirect records of ``root/folder``: those with each method's own
    hyperparameters by default, the tuned ones with ``tuned=True``, all with ``None``."""
    return [r for r in read_records(Path(root) / folder) if r.experiment == INDIRECT
            and (tuned is None or r.tuned == tuned)]


def block(name: str):
    """Register ``f(root) -> str`` as the generator of the blocks named ``name``."""

    def register(fn: Callable[[Path], str]) -> Callable[[Path], str]:
        if name in GENERATORS:
            raise ValueError(f"a page block named {name!r} is registered twice")
        GENERATORS[name] = fn
        return fn

    return register


def render(root: Path, name: str, made: dict[str, str] | None = None) -> str:
    """Block ``name``'s text made from the records under ``root`` (once per name in ``made``)."""
    if name not in GENERATORS:
        raise UserError(f"no generator makes the page block {name!r}; there are: {', '.join(sorted(GENERATORS))}")
    made = {} if made is None else made
    if name not in made:
        text = GENERATORS[name](Path(root))
        made[name] = text if text.endswith("\n") else text + "\n"
    return made[name]


def rewrite(text: str, root: Path, made: dict[str, str] | None = None) -> str:
    """``text`` with each generated block made again."""
    made = {} if made is None else made
    return BLOCK.sub(lambda m: m["open"] + render(root, m["name"], made) + m["close"], text)


def stale_blocks(root: Path, pages: list[Path]) -> list[str]:
    """``page: block NAME differs from its records`` for each generated block that
    is not what its generator makes now."""
    made: dict[str, str] = {}
    out = []
    for page in pages:
        for m in BLOCK.finditer(page.read_text()):
            if render(root, m["name"], made) != m["body"]:
                out.append(f"{page}: block {m['name']} differs from what its records give (python -m bench index)")
    return out

