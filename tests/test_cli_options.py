"""Every command-line flag reaches its config field, and the defaults are the config's own."""

from __future__ import annotations

import argparse
import dataclasses
import re

import pytest

from curate import cli
from curate.core.options import NO_CONST, Opt, apply_options, get_path

# arguments of each command that are inputs, outputs or switches, not config options
NOT_CONFIG = {"-h", "--help", "--out", "--poses", "--force", "--json", "--list", "--executor", "--ray-address",
              "--jobs", "--adopt"}
POSITIONAL = {"sfm": [], "run": [], "score": ["x.json"], "select": ["x.json"], "batch": [], "occupancy": ["RUN"],
              "suggest": ["RUN"],
              "evaluate": ["RUN"], "export": ["RUN"], "report": ["RUN"], "simulate": []}
REQUIRED = {"sfm": ["--out", "o"], "run": ["--out", "o"], "batch": ["--out", "o"], "simulate": ["--out", "o"]}


def _other_value(opt: Opt, current):
    """A command-line text and the value it must produce, different from ``current``."""
    if opt.const is not NO_CONST:
        return None, opt.const
    if opt.choices:
        v = next(c for c in opt.choices if c != current)
        return str(v), v
    if opt.flag == "--budget" and isinstance(current, str):
        return ("37" if current != "37" else "12%"), ("37" if current != "37" else "12%")
    if opt.flag == "--bins":
        return "3x7", (3, 7)
    if opt.flag == "--box":
        return "-1,-2,-3,4,5,6", (-1.0, -2.0, -3.0, 4.0, 5.0, 6.0)
    if opt.flag == "--size":
        from curate.simulate.progressive import CameraSpec
        return "96x64", CameraSpec(96, 64)
    if opt.flag == "--methods":
        return "ours,fvs", ("ours", "fvs")
    if opt.flag == "--device":
        return "cpu", "cpu"
    if opt.flag == "--downscale":
        return "2,4", (2, 4)
    if isinstance(current, bool):
        return ("--no-" if current else "--"), (not current)
    if isinstance(current, float):
        return repr(current * 1.5 + 0.25), current * 1.5 + 0.25
    if isinstance(current, int) or current is None:
        v = (current or 0) + 3
        return str(v), v
    raise AssertionError(f"no test value for {opt.flag} (default {current!r})")


def _cases():
    for cmd, opts in cli.COMMAND_OPTS.items():
        for o in opts:
            yield pytest.param(cmd, o, id=f"{cmd}{o.flag}")


@pytest.mark.parametrize("cmd, opt", list(_cases()))
def test_every_flag_reaches_its_config(cmd, opt):
    base = cli._base_for(cmd)
    current = tuple(get_path(base, p) for p in opt.paths) if isinstance(opt.path, tuple) else get_path(base, opt.path)
    text, want = _other_value(opt, current)
    if text is None:
        flag_args = [opt.flag]
    elif text in ("--", "--no-"):
        flag_args = [text + opt.flag[2:]]
    else:
        flag_args = [f"{opt.flag}={text}"]   # the = form: values such as -1,-2,... are not taken for flags
    argv = [cmd, *POSITIONAL[cmd], *REQUIRED.get(cmd, []), *flag_args]
    args = cli.build_parser(cmd).parse_args(argv)
    cfg = apply_options(base, args, cli.COMMAND_OPTS[cmd])
    got = tuple(get_path(cfg, p) for p in opt.paths) if isinstance(opt.path, tuple) else get_path(cfg, opt.path)
    assert got == want and got != current
    # and nothing else moved: the other fields keep the base's values
    others = dataclasses.replace(cfg)
    for p in opt.paths:
        from curate.core.options import set_path
        others = set_path(others, p, get_path(base, p))
    assert others == base


@pytest.mark.parametrize("cmd", list(cli.COMMANDS))
def test_every_option_of_every_command_is_a_config_field_or_an_input(cmd):
    """A flag that is neither bound to a config field nor a known input/output is a flag that reaches nothing."""
    p = cli.build_parser(cmd)
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[cmd]
    bound = {o.flag for o in cli.COMMAND_OPTS[cmd]}
    for a in sub._actions:
        for s in a.option_strings:
            if s.startswith("--no-") and s[:2] + s[5:] in bound:
                continue
            assert s in bound or s in NOT_CONFIG, f"curate {cmd} {s} reaches no config"


@pytest.mark.parametrize("cmd", list(cli.COMMANDS))
def test_no_flag_given_leaves_the_config_as_it_is(cmd):
    """A saved run's options are the base of a re-run: flags not given must not reset them."""
    base = cli._base_for(cmd)
    opts = cli.COMMAND_OPTS[cmd]
    changed = base
    for o in opts:   # a base that differs from the defaults everywhere it can
        cur = tuple(get_path(base, p) for p in o.paths) if isinstance(o.path, tuple) else get_path(base, o.path)
        _, v = _other_value(o, cur)
        from curate.core.options import set_path
        if isinstance(o.path, tuple):
            for p, x in zip(o.path, v):
                changed = set_path(changed, p, x)
        else:
            changed = set_path(changed, o.path, v)
    args = cli.build_parser(cmd).parse_args([cmd, *POSITIONAL[cmd], *REQUIRED.get(cmd, [])])
    assert apply_options(changed, args, opts) == changed


def test_defaults_in_help_are_the_configs():
    """--help shows the dataclass default (declared once), e.g. --iters 800 and --holdout-every 14."""
    from curate.config import RunConfig
    text = cli.build_parser("run")._subparsers._group_actions[0].choices["run"].format_help()
    cfg = RunConfig()
    assert f"(default: {cfg.evaluate.iters})" in " ".join(text.split())
    assert "--holdout-every" in text and f"(default: {cfg.evaluate.holdout_every})" in " ".join(text.split())


def test_help_and_version_are_instant_and_light():
    """`curate --help` and `--version` import no heavy module (torch, pycolmap, open3d)."""
    import subprocess
    import sys
    code = ("import sys; from curate import cli\n"
            "try:\n    cli.main(['--version'])\nexcept SystemExit: pass\n"
            "try:\n    cli.main(['--help'])\nexcept SystemExit: pass\n"
            "print([m for m in ('torch', 'pycolmap', 'open3d', 'numpy') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "curate 0." in out and out.strip().splitlines()[-1] == "[]"


@pytest.mark.parametrize("cmd", cli.COMMANDS)
def test_a_commands_help_imports_no_torch_pycolmap_or_open3d(cmd):
    """Issue 51: `curate run --help` loaded torch (3.4 s of imports before the help appeared): the options live in
    light config modules."""
    import subprocess
    import sys
    code = ("import sys; from curate import cli\n"
            f"try:\n    cli.main([{cmd!r}, '--help'])\nexcept SystemExit: pass\n"
            "print([m for m in ('torch', 'pycolmap', 'open3d') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "usage:" in out and out.strip().splitlines()[-1] == "[]"


# ---------------------------------------------------------------------- --help reads like a tool's, not like code
CODE_NAMES = {
    "a constant (CAPS_WITH_UNDERSCORES)": r"\b[A-Z][A-Z0-9]*_[A-Z0-9_]*\b",
    "an identifier with underscores": r"\b[a-z][a-z0-9]*_[a-z0-9_]+\b",
    "a function call": r"\b\w+\(\)",
    "a Python value": r"\b(None|True|False)\b",
    "a module path": r"\bcurate\.\w+",
    "reStructuredText markup": r"``|:func:|:class:|:mod:|:data:",
    "an unrounded float": r"\d\.0*[1-9]\d{5,}",
}


def _help_of(cmd: str | None) -> tuple[str, argparse.ArgumentParser]:
    p = cli.build_parser(cmd)
    if cmd is None:
        return p.format_help(), p
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[cmd]
    return sub.format_help(), sub


@pytest.mark.parametrize("cmd", [None, *cli.COMMANDS])
def test_help_shows_no_code_names_and_one_default_per_option(cmd):
    """`curate [COMMAND] --help` speaks to a user: no constants, identifiers, Python values or
    module paths (the values a flag takes, such as per_image, excepted), floats rounded, and
    never two "(default: ...)" for one option."""
    text, parser = _help_of(cmd)
    choices = {str(c) for a in parser._actions for c in (a.choices or ()) if isinstance(c, str)}
    flat = " ".join(text.split())
    for what, pattern in CODE_NAMES.items():
        bad = sorted({m.group(0) for m in re.finditer(pattern, flat)} - choices)
        assert not bad, f"curate {cmd or ''} --help shows {what}: {bad}"
    for a in parser._actions:
        assert (a.help or "").count("(default") <= 1, f"{a.option_strings}: {a.help}"


def test_help_lists_run_first_and_ends_with_examples():
    text, _ = _help_of(None)
    section = text.split("commands:")[1].split("examples:")[0]
    listed = re.findall(r"^    (\w+) ", section, re.M)
    assert listed[:3] == ["run", "sfm", "select"] and set(listed) == set(cli.COMMANDS)
    tail = text.split("examples:")[1]
    assert tail.count("curate run ") >= 2 and "curate select " in tail


def test_method_help_has_one_line_per_method_from_the_registry():
    """--method's choices and help come from curate.select.methods.REGISTRY: one line per method."""
    from curate.select.methods import REGISTRY
    text, parser = _help_of("run")
    action = next(a for a in parser._actions if "--method" in a.option_strings)
    assert tuple(action.choices) == tuple(REGISTRY)
    block = text.split("\n  --method {")[1].split("\n  --")[0]
    assert re.findall(r"^\s+(\w+)  +\S", block, re.M) == list(REGISTRY)


def test_a_saved_run_of_an_earlier_curate_keeps_its_export_mode():
    """curate 0.3 saved `export_mode`; it is now `export.mode` (ExportConfig), and a stage re-run keeps it."""
    from curate.config import RunConfig, upgrade_config
    from curate.core.stage import config_from_dict
    cfg = config_from_dict(RunConfig, upgrade_config({"budget": "12", "export_mode": "copy"}, "0.3.0"))
    assert cfg.export.mode == "copy" and cfg.export.undistort == "auto" and cfg.budget == "12"
    assert config_from_dict(RunConfig, upgrade_config({}, "0.3.0")).export.mode == "hardlink"


# ---------------------------------------------------------------------- one style of field documentation
def _option_dataclasses() -> list[type]:
    """The option dataclasses: RunConfig, SfmConfig and the base config of every command, with every dataclass
    held by their fields' defaults (recursively)."""
    from curate.config import RunConfig
    from curate.sfm.config import SfmConfig

    todo = [RunConfig(), SfmConfig(), *(cli._base_for(cmd) for cmd in cli.COMMANDS)]
    seen: list[type] = []
    while todo:
        cfg = todo.pop()
        if type(cfg) in seen:
            continue
        seen.append(type(cfg))
        todo += [v for f in dataclasses.fields(cfg) for v in [getattr(cfg, f.name)]
                 if dataclasses.is_dataclass(v) and not isinstance(v, type)]
    return seen


def test_every_option_field_has_an_attribute_docstring():
    """Issue 51: one style of field documentation. The help of every field of every option dataclass is the
    string right after it (its first paragraph is the flag's --help); a trailing # comment is not read."""
    from curate.core.options import field_docs
    classes = _option_dataclasses()
    names = {c.__name__ for c in classes}
    assert {"RunConfig", "SfmConfig", "VideoConfig", "EvalConfig", "FieldConfig", "SelectConfig", "EnergyConfig",
            "OccupancyConfig", "RefineConfig", "ExportConfig", "SuggestConfig", "SimulateConfig"} <= names
    missing = [f"{c.__qualname__}.{f.name}" for c in classes for f in dataclasses.fields(c)
               if not field_docs(c).get(f.name)]
    assert not missing, f"fields without an attribute docstring: {missing}"


def _field_type(cfg, path: str):
    """The type hint of the config field ``path`` ("sfm.matcher") of the config object ``cfg``."""
    import sys
    *owners, name = path.split(".")
    for o in owners:
        cfg = getattr(cfg, o)
    f = next(f for f in dataclasses.fields(cfg) if f.name == name)
    return eval(f.type, vars(sys.modules[type(cfg).__module__])) if isinstance(f.type, str) else f.type


def test_every_choice_is_declared_once_as_the_fields_literal():
    """Issue 51: a flag's choices are its config field's ``Literal[...]`` (the tuple the CLI offers is derived
    from it), so the choices, the validation and the help cannot drift apart. The method's choices come from
    the method registry (a field of type str checked against it)."""
    import typing
    seen = []
    for cmd, opts in cli.COMMAND_OPTS.items():
        base = cli._base_for(cmd)
        for o in opts:
            if not o.choices or o.flag == "--method":
                continue
            hint = _field_type(base, o.path)
            assert typing.get_origin(hint) is typing.Literal, f"{cmd} {o.flag}: {hint} is not a Literal"
            assert tuple(o.choices) == typing.get_args(hint), f"{cmd} {o.flag}"
            seen.append(o.flag)
    assert {"--matcher", "--mapper", "--on-split", "--triangulate", "--camera-mode", "--undistort"} <= set(seen)
