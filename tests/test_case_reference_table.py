"""The how-to's table of a case's settings lists every key of a case file with its default,
as the configuration has them (a key added or a default changed shows here)."""

import re
from pathlib import Path

from pydantic import BaseModel

from cfbmarkov.config import CaseConfig

PAGE = Path(__file__).resolve().parents[1] / "docs" / "how-to" / "own-case.md"


def _as_toml(value) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(_as_toml(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return f"{value:g}" if isinstance(value, float) else str(value)


def _settings() -> dict[str, str]:
    out = {}
    for name, field in CaseConfig.model_fields.items():
        table = field.annotation
        if isinstance(table, type) and issubclass(table, BaseModel):
            out.update({f"{name}.{key}": _as_toml(f.default)
                        for key, f in table.model_fields.items()})
        else:
            out[name] = _as_toml(field.default)
    return out


def test_every_setting_and_its_default_is_in_the_table():
    rows = dict(re.findall(r"^\| `([a-z_.]+)` \| `([^`]*)` \|", PAGE.read_text(), re.M))
    assert rows == _settings()
