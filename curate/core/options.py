"""Command-line options read from the config dataclasses: each default and help text is declared once.

A config dataclass documents each field with an attribute docstring (a string right after
the field; a ``#`` comment is not read). The docstring's first paragraph is the flag's
``--help`` text, written for a user (no code names); a later paragraph, after a blank line,
is a note for developers that ``--help`` leaves out. :class:`Opt` names a flag
and the dotted path of the field it sets (``"evaluate.iters"``); :func:`add_options` adds it
to an argparse parser with the field's default and help, and :func:`apply_options` writes
the flags the user gave (and only those) into a config, so a saved run's options stay the
base of every stage re-run. :class:`HelpFormatter` keeps the line breaks of a help text
that has them (``--method``: one line per method).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import re
import textwrap
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, Sequence


NO_CONST = object()
"""Marks an :class:`Opt` that takes a value (the default of ``Opt.const``)."""


@dataclass(frozen=True)
class Opt:
    """One command-line flag bound to config field(s)."""

    flag: str
    """The flag, e.g. ``--iters``."""
    path: str | tuple[str, ...]
    """Dotted path of the field it sets in the root config (a tuple: the parsed value is a
    tuple, one item per path, e.g. ``--bins 5x10``)."""
    parse: Callable[[str], Any] | None = None
    """argparse ``type`` (default: the type of the field's default value)."""
    const: Any = NO_CONST
    """A flag without a value that stores this constant (e.g. ``--no-evaluate`` stores False)."""
    choices: Sequence[Any] | None = None
    """Allowed values."""
    help: str | None = None
    """Help text (default: the field's docstring)."""
    metavar: str | None = None
    """Name of the value in the help."""

    @property
    def paths(self) -> tuple[str, ...]:
        return self.path if isinstance(self.path, tuple) else (self.path,)

    @property
    def dest(self) -> str:
        return "opt_" + self.flag.lstrip("-").replace("-", "_")


def _clean(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


def _user_part(doc: str) -> str:
    """The first paragraph of a docstring (the user's part; what follows a blank line is for developers)."""
    return _clean(re.split(r"\n\s*\n", inspect.cleandoc(doc), maxsplit=1)[0])


@lru_cache(maxsize=None)
def field_docs(cls: type) -> dict[str, str]:
    """{field name: its help} of a dataclass: the first paragraph of the attribute docstring
    after the field (a field without one is left out)."""
    try:
        src = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):  # pragma: no cover - no source (frozen app)
        return {}
    body = ast.parse(src).body[0].body  # type: ignore[attr-defined]
    out: dict[str, str] = {}
    for node, nxt in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str)):
            out[node.target.id] = _user_part(nxt.value.value)
    return out


def get_path(cfg: Any, path: str) -> Any:
    for part in path.split("."):
        cfg = getattr(cfg, part)
    return cfg


def set_path(cfg: Any, path: str, value: Any) -> Any:
    """A copy of the dataclass ``cfg`` with the field at ``path`` set to ``value``
    (nested dataclasses are copied too; ``__post_init__`` checks run)."""
    head, _, rest = path.partition(".")
    if rest:
        value = set_path(getattr(cfg, head), rest, value)
    return dataclasses.replace(cfg, **{head: value})


def field_of(cfg: Any, path: str) -> tuple[type, str]:
    """(the dataclass that declares the field at ``path``, the field's name)."""
    *parents, name = path.split(".")
    owner = cfg
    for p in parents:
        owner = getattr(owner, p)
    return type(owner), name


def doc_of(cfg: Any, path: str) -> str:
    cls, name = field_of(cfg, path)
    for klass in cls.__mro__:
        if dataclasses.is_dataclass(klass):
            d = field_docs(klass).get(name)
            if d:
                return d
    return ""


def _show(v: Any) -> str:
    """A default as a user reads it: 5x10, 0.006667 (not 0.006666666666666667), on / off, none."""
    if hasattr(v, "width") and hasattr(v, "height"):
        return f"{v.width}x{v.height}"
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, tuple):
        return "x".join(map(str, v)) if all(isinstance(x, int) for x in v) else ",".join(map(_show, v))
    return "none" if v is None else str(v)


def _esc(text: str) -> str:
    return text.replace("%", "%%")


def brief(doc: str) -> str:
    """A field's help as ``--help`` prints it: without reStructuredText markup or a final full stop,
    starting in lower case like argparse's own lines (an acronym such as SIFT keeps its capitals)."""
    doc = re.sub(r":\w+:`~?([^`]+)`", lambda m: m.group(1).rsplit(".", 1)[-1], doc)
    doc = doc.replace("``", "").strip().rstrip(".")
    if len(doc) > 1 and doc[0].isupper() and not (doc[1].isupper() or doc[1].isdigit()):
        doc = doc[0].lower() + doc[1:]
    return doc


def _default_note(text: str, default: Any) -> str:
    """`` (default: X)``, unless there is no default or the text already says it."""
    return "" if default is None or "(default" in text else f" (default: {_show(default)})"


def _metavar(o: "Opt", default: Any) -> str:
    """The value's name in ``--help``: the Opt's own, else N (a whole number), X (a number) or the flag's word."""
    if o.metavar:
        return o.metavar
    if isinstance(default, int) and not isinstance(default, bool):
        return "N"
    if isinstance(default, float):
        return "X"
    return o.flag.lstrip("-").split("-")[-1].upper()


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, but a text with line breaks keeps them (an option's help, a
    description, the examples of an epilog): each line is wrapped on its own, continuation
    lines indented under the text after a leading key ("path   frames...")."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n" not in text:
            return super()._fill_text(text, width, indent)
        return "\n".join(indent + line for line in self._split_lines(text, width - len(indent)))

    def _split_lines(self, text: str, width: int) -> list[str]:
        if "\n" not in text:
            return super()._split_lines(text, width)
        out: list[str] = []
        for line in text.splitlines():
            m = re.match(r"(\s*)(\S+\s{2,})?", line)
            hang = m.end() if m.group(2) else len(m.group(1)) + 2 * bool(m.group(1))
            out += textwrap.wrap(line, width, subsequent_indent=" " * hang) or [""]
        return out


def add_options(parser: argparse.ArgumentParser | Any, base: Any, opts: Sequence[Opt]) -> None:
    """Add ``opts`` to ``parser``; defaults and help come from ``base`` (a config instance)
    and its fields' docstrings. A flag the user does not give leaves no attribute (its
    value stays whatever the config it is applied to holds)."""
    for o in opts:
        default = tuple(get_path(base, p) for p in o.paths) if isinstance(o.path, tuple) else get_path(base, o.path)
        text = o.help if o.help is not None else brief(doc_of(base, o.paths[0]))
        kw: dict[str, Any] = {"dest": o.dest, "default": argparse.SUPPRESS}
        if o.const is not NO_CONST:
            parser.add_argument(o.flag, action="store_const", const=o.const, help=_esc(text), **kw)
            continue
        if isinstance(default, bool) and o.parse is None:
            parser.add_argument(o.flag, action=argparse.BooleanOptionalAction,
                                help=_esc(text + _default_note(text, default)), **kw)
            continue
        typ = o.parse or (type(default) if default is not None and not isinstance(default, tuple) else str)
        parser.add_argument(o.flag, type=typ, choices=o.choices, metavar=None if o.choices else _metavar(o, default),
                            help=_esc(text + _default_note(text, default)), **kw)


def given(args: argparse.Namespace, opts: Sequence[Opt]) -> list[Opt]:
    """The options of ``opts`` that the user gave on the command line."""
    return [o for o in opts if hasattr(args, o.dest)]


def apply_options(cfg: Any, args: argparse.Namespace, opts: Sequence[Opt]) -> Any:
    """``cfg`` with the value of every flag of ``opts`` that the user gave."""
    for o in given(args, opts):
        v = getattr(args, o.dest)
        if isinstance(o.path, tuple):
            for p, x in zip(o.path, v):
                cfg = set_path(cfg, p, x)
        else:
            cfg = set_path(cfg, o.path, v)
    return cfg
