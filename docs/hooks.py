"""MkDocs hook: the tables that come from the code, so that they cannot drift from it.

A page line `<!-- generated: NAME -->` is replaced by the table NAME makes: `flags` (every
flag of each `ldn-jax` subcommand, from its argparse parser), `fields` (every config field
with its type, default and docstring), `presets` (what each preset sets) and `precedence`
(the order of the config layers, from `ldn_jax.presets`' docstring).
"""

from __future__ import annotations

import argparse
import re

from ldn_jax import config, presets
from ldn_jax.host import cli, settings

MARKER = re.compile(r"^<!-- generated: (\w+) -->$", re.M)


def on_page_markdown(markdown: str, **_) -> str:
    return MARKER.sub(lambda m: TABLES[m.group(1)](), markdown)


def _cell(text: object) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def flags_table() -> str:
    blocks = []
    for command, parser in cli.parsers().items():
        rows = ["| flag | value | default | what it does |", "|---|---|---|---|"]
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            name = ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.dest}`"
            if action.choices:
                value = "{" + ",".join(map(str, action.choices)) + "}"
            elif action.nargs == 0:
                value = ""
            else:
                value = action.metavar or action.dest.upper()
            default = action.default
            shown = "" if default in (None, False, [], argparse.SUPPRESS) else f"`{default}`"
            rows.append(f"| {name} | {_cell(value)} | {_cell(shown)} | {_cell(action.help)} |")
        blocks.append(f"### `{command}`\n\n" + "\n".join(rows))
    return "\n\n".join(blocks)


def fields_table() -> str:
    docs, defaults = settings.field_docs(), config.Config()
    rows = ["| field | type | default | what it is |", "|---|---|---|---|"]
    for name, kind in config.fields().items():
        value = settings.as_text(config.get_field(defaults, name))
        what = docs.get(name, "")
        if name in config.CHOICES:
            what += " One of: " + ", ".join(f"`{c}`" for c in config.CHOICES[name]) + "."
        rows.append(f"| `{name}` | {kind.describe()} | `{value}` | {_cell(what)} |")
    return "\n".join(rows)


def presets_table() -> str:
    rows = ["| preset | for | sets |", "|---|---|---|"]
    for name, entry in presets.PRESETS.items():
        parts = [f"`{k}={settings.as_text(v)}`" for k, v in presets.own_fields(entry).items()]
        for kind in ("learners", "envs"):
            for key, values in entry.get(kind, {}).items():
                own = presets.own_fields(values)
                inner = ", ".join(f"`{k}={settings.as_text(v)}`" for k, v in own.items())
                for learner, fields in values.get("learners", {}).items():
                    listed = ", ".join(f"`{k}={settings.as_text(v)}`" for k, v in fields.items())
                    inner += f"; with {learner}: {listed}"
                parts.append(f"{key}: {inner}")
        sets = "; ".join(parts) or "nothing: the defaults are the paper's"
        rows.append(f"| `{name}` | {_cell(presets.PRESET_PURPOSE[name])} | {sets} |")
    return "\n".join(rows)


def precedence() -> str:
    text = presets.__doc__.split("\n\n", 1)[1]
    return text.split("`ldn-jax --explain FIELD`")[0].strip()


TABLES = {
    "flags": flags_table,
    "fields": fields_table,
    "presets": presets_table,
    "precedence": precedence,
}
