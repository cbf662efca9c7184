"""Config fields by their dotted names, from text: `--config` files, `--set` and `--sweep`
values, and `--list-fields`.

The names and types are `ldn_jax.config.fields()`'s, read off the dataclasses' annotations,
so a new field is settable the day it is added. A value that does not fit its field, or a
field that does not exist, is a `UsageError` naming the closest field.
"""

from __future__ import annotations

import ast
import difflib
import inspect
import itertools
import json
import re
import textwrap
import tomllib
from pathlib import Path

from ldn_jax.config import PRESETS, SECTIONS, Config, FieldType, canonical, fields, get_field


class UsageError(Exception):
    """Bad input: reported as one line on stderr with exit code 2."""


def read_config_file(path: str) -> tuple[str | None, dict[str, tuple[object, str]]]:
    """`--config FILE`: its preset (None if it names none) and `{dotted name: (value,
    where)}`. TOML or JSON, by the name's suffix; sections `agent` and `model` nest as in
    config.json, whose `run_format` is not a setting and is skipped."""
    file = Path(path)
    try:
        text = file.read_text()
    except OSError as error:
        raise UsageError(f"--config {path}: {error.strerror or error}") from None
    try:
        if file.suffix == ".toml":
            data = tomllib.loads(text)
        elif file.suffix == ".json":
            data = json.loads(text)
        else:
            raise UsageError(f"--config {path}: expected a .toml or .json file")
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as error:
        raise UsageError(f"--config {path}: not valid {file.suffix[1:].upper()}: {error}") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a table of config fields")
    data.pop("run_format", None)
    preset = data.pop("preset", None)
    sweep = data.pop("sweep", None)
    if preset is not None and not isinstance(preset, str):
        raise UsageError(f"--config {path}: preset must be a string, got {preset!r}")
    flat = {}
    for key, value in data.items():
        if key in SECTIONS:
            if not isinstance(value, dict):
                raise UsageError(f"--config {path}: {key} must be a table of its fields")
            flat |= {canonical(f"{key}.{sub}"): v for sub, v in value.items()}
        else:
            flat[key] = value
    where = f"--config {path}"
    settings = {name: (check_value(name, v, where), where) for name, v in flat.items()}
    if sweep is not None:
        settings["sweep"] = (check_sweep(sweep, where), where)
    return preset, settings


def parse_sweep(item: str) -> tuple[str, tuple[float, ...]]:
    """`--sweep FIELD=V1,V2,...` -> `(field, values)`; which fields may be swept is
    `validate`'s to say."""
    name, sep, text = item.partition("=")
    name = canonical(name.strip())
    field_type(name, f"--sweep {item}")  # an unknown field: one line, the closest named
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        values = ()
    if not sep or not values:
        raise UsageError(f"--sweep needs FIELD=V1,V2,... with numbers, got {item!r}")
    return name, values


def check_sweep(sweep, where: str) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """A file's sweep: config.json's `[[field, [values]], ...]`, or a table
    `{field: [values]}` (TOML's `[sweep]`)."""
    pairs = sweep.items() if isinstance(sweep, dict) else sweep
    try:
        out = []
        for name, values in pairs:
            name = canonical(name)
            field_type(name, where)
            if not all(_is(float, v) for v in values):
                raise TypeError
            out.append((name, tuple(float(v) for v in values)))
    except (TypeError, ValueError):
        raise UsageError(
            f"{where}: sweep must be a table of field = [values] or config.json's "
            f"[[field, [values]], ...], got {sweep!r}"
        ) from None
    return tuple(out)


def field_type(name: str, where: str) -> FieldType:
    """The type of the config field `name`; UsageError naming the closest field if none."""
    table = fields()
    if name not in table:
        close = difflib.get_close_matches(name, table, n=1)
        hint = f"; did you mean {close[0]}?" if close else ""
        raise UsageError(f"{where}: unknown config field {name!r}{hint} (--list-fields)")
    return table[name]


def parse_value(name: str, text: str, where: str):
    """The command line's text for field `name` as a value of its type, or UsageError."""
    kind = field_type(name, where)
    if kind.optional and text.lower() in ("none", "null"):
        return None
    if kind.sequence:
        return tuple(_scalar(kind, part.strip(), name, where) for part in text.split(","))
    return _scalar(kind, text, name, where)


def _scalar(kind: FieldType, text: str, name: str, where: str):
    try:
        if kind.base is bool:
            return {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}[
                text.lower()
            ]
        return kind.base(text)
    except (KeyError, ValueError):
        raise UsageError(f"{where}: {name} takes {kind.describe()}, got {text!r}") from None


def check_value(name: str, value, where: str):
    """A file's value for field `name`, checked against its type (an int is a float;
    'none' is None where None is allowed), or UsageError."""
    kind = field_type(name, where)
    if kind.optional and (value is None or value == "none"):
        return None
    items = value if kind.sequence and isinstance(value, list) else [value]
    ok = all(_is(kind.base, v) for v in items) and (isinstance(value, list) or not kind.sequence)
    if not ok:
        raise UsageError(f"{where}: {name} takes {kind.describe()}, got {value!r}")
    cast = [kind.base(v) for v in items]
    return tuple(cast) if kind.sequence else cast[0]


def _is(base: type, value) -> bool:
    """Whether a file's `value` is one of `base` (JSON and TOML: a bool is no number)."""
    if isinstance(value, bool) or base is bool:
        return isinstance(value, bool) and base is bool
    accepted = {float: (int, float), int: int, str: str}[base]
    return isinstance(value, accepted)


def list_fields(config: Config, sources: dict[str, str] | None = None) -> list[str]:
    """`--list-fields`: one line per config field: its name, type, value in `config` (as
    `--set` takes it), the layer that set it (`sources`, `ldn_jax.config.resolution`'s names;
    left out where None) and the first sentence of its docstring."""
    table, docs, sources = fields(), field_docs(), sources or {}
    width = max(map(len, table))
    setters = max((len(s) for s in sources.values()), default=0) + 2 if sources else 0
    by = lambda name: f"{'[' + sources[name] + ']':<{setters}}  " if name in sources else ""
    lines = [f"{'preset':<{width}}  {'str':<24}  {config.preset:<12}  one of: {', '.join(PRESETS)}"]
    swept = " ".join(f"{n}={as_text(v)}" for n, v in config.sweep) or "none"
    lines.append(f"{'sweep':<{width}}  {'--sweep FIELD=V1,V2':<24}  {swept:<12}  vmapped grid")
    for name, kind in table.items():
        value = as_text(get_field(config, name))
        line = f"{name:<{width}}  {kind.describe():<24}  {value:<12}  {by(name)}"
        lines.append(line + docs.get(name, ""))
    return lines


def as_text(value) -> str:
    """A value as `--set` takes it."""
    if value is None:
        return "none"
    if isinstance(value, tuple):
        return ",".join(f"{v:g}" for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def field_docs() -> dict[str, str]:
    """The first sentence of each config field's docstring (the string below it in
    `ldn_jax.config`), by dotted name."""
    docs = {}
    for prefix, cls in [("", Config), *((f"{n}.", c) for n, c in SECTIONS.items())]:
        body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
        for node, after in itertools.pairwise(body):
            if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                text = getattr(after, "value", None)
                if isinstance(text, ast.Constant) and isinstance(text.value, str):
                    first = re.split(r"\.\s+(?=[A-Z])", " ".join(text.value.split()))[0]
                    docs[prefix + node.target.id] = first.rstrip(".") + "."
    return docs
