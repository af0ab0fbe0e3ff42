"""File schemas: the base of every validated file and settings section, and reading and
writing mappings as YAML or JSON.

Every room's files (calibration, compensation models, settings, reports) go through here, so
a bad file is always one line that names it and the field: ``calib.yaml: thermal.fx: Input
should be greater than or equal to 1 (got -150.5)``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from .errors import InputError, read_text, repeated
from .radiometry import PlanckConstants

Finite = Annotated[float, Field(allow_inf_nan=False)]
"""A number that is neither NaN nor infinite."""


class StrictSchema(BaseModel):
    """Base of every file and settings schema: unknown keys, NaN and infinities refused."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class PlanckSchema(StrictSchema):
    """A camera's counts calibration S = O + R / (exp(B / T) - F) as written in files
    (:class:`~thermodepth.radiometry.PlanckConstants`)."""

    R: float = Field(gt=0)
    B: float = Field(gt=0)
    F: float
    O: float  # noqa: E741 (the paper's and FLIR's name)

    def constants(self) -> PlanckConstants:
        return PlanckConstants(**self.model_dump())

    @classmethod
    def of(cls, planck: PlanckConstants) -> dict[str, float]:
        """The mapping a file holds for ``planck``."""
        return {"R": planck.R, "B": planck.B, "F": planck.F, "O": planck.O}


def _describe_input(value: Any) -> str:
    return "nothing" if value is None else repr(value)


def validation_lines(exc: ValidationError) -> list[str]:
    """Each problem of a pydantic validation as one line: ``field.path: message``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        if err["type"] == "missing":
            msg = "missing"
        elif err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] in ("model_type", "model_attributes_type", "dict_type"):
            # pydantic names its own class here ("instance of CameraSchema"): say what is wanted
            msg = f"expected a mapping of keys, got {_describe_input(err.get('input'))}"
        else:
            msg = err["msg"].removeprefix("Value error, ")
            # a whole mapping (a check across its keys) would print the whole file section
            if "input" in err and not isinstance(err["input"], dict):
                msg += f" (got {err['input']!r})"
        lines.append(f"{loc}: {msg}" if loc else msg)
    return lines


def describe_validation_error(exc: ValidationError) -> str:
    """One line for the first problem of a pydantic validation (:func:`validation_lines`),
    saying how many more there are."""
    lines = validation_lines(exc)
    more = len(lines) - 1
    return lines[0] + (f" [and {more} more problem{'s' if more > 1 else ''}]" if more else "")


S = TypeVar("S", bound=BaseModel)


def validated(schema: type[S], data: Any, where: str, prefix: str = "") -> S:
    """``data`` validated against ``schema``; a bad value raises one InputError line naming
    ``where`` (a file) and the field (after ``prefix``, e.g. ``model.``)."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise InputError(f"{where}: {prefix}{describe_validation_error(exc)}") from None


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object as a dict; a key given twice raises (json keeps the last, silently)."""
    twice = repeated(k for k, _ in pairs)
    if twice:
        raise ValueError(f"key {', '.join(map(repr, twice))} given twice")
    return dict(pairs)


def read_mapping(path: str | Path) -> dict[str, Any]:
    """Parse a YAML or JSON file (JSON when the name ends in .json); unreadable or malformed
    files, and files whose top level is not a mapping, raise a one-line InputError."""
    p = Path(path)
    text = read_text(p)
    is_json = p.suffix.lower() == ".json"
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys) if is_json else yaml.safe_load(text)
    except RecursionError:
        raise InputError(f"{p}: nested too deeply to read") from None
    except (ValueError, yaml.YAMLError) as exc:  # JSONDecodeError; an integer of 5000 digits
        first = str(exc).strip().splitlines()[0]
        raise InputError(f"{p}: not valid {'JSON' if is_json else 'YAML'}: {first}") from None
    if not isinstance(data, dict):
        raise InputError(f"{p}: expected a mapping of keys at the top level")
    return data


def load_validated(schema: type[S], path: str | Path, prefix: str = "") -> S:
    """A YAML or JSON file read (:func:`read_mapping`) and validated (:func:`validated`)."""
    return validated(schema, read_mapping(path), str(path), prefix)


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, and tuples, as the Python numbers and lists they hold."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"cannot write a {type(value).__name__}")


class _Dumper(yaml.SafeDumper):
    """YAML's safe dumper, writing numpy values and tuples as plain numbers and lists."""


for _kind in (np.ndarray, np.generic, tuple):
    _Dumper.add_multi_representer(_kind, lambda dumper, v: dumper.represent_data(_plain(v)))


def write_mapping(path: str | Path, data: dict[str, Any]) -> None:
    """Write a mapping as JSON (a name ending in .json) or YAML; numpy values become plain."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.suffix.lower() == ".json":
        p.write_text(json.dumps(data, indent=2, default=_plain) + "\n", encoding="utf-8")
    else:
        p.write_text(yaml.dump(data, Dumper=_Dumper, sort_keys=False), encoding="utf-8")
