"""Model files: a versioned mapping (JSON, or YAML by the file's name) holding the method and
the model's own fields."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from ..errors import InputError
from ..schema import describe_validation_error, read_mapping, write_mapping
from .base import CompensationModel
from .registry import COMPENSATION_METHODS

SCHEMA = "thermodepth.compensation"
SCHEMA_VERSION = 1


def save_model(model: CompensationModel, path: str | Path) -> None:
    """Write a model as a versioned mapping: JSON, or YAML when the name ends otherwise."""
    doc = {
        "schema": SCHEMA,
        "version": SCHEMA_VERSION,
        "method": model.method,
        "model": model.to_dict(),
    }
    write_mapping(path, doc)


def load_model(path: str | Path) -> CompensationModel:
    """Read and validate a model file (JSON or YAML); a bad file raises one InputError line
    naming it and the field."""
    p = Path(path)
    doc = read_mapping(p)
    if doc.get("schema") != SCHEMA:
        raise InputError(f"{p}: not a thermodepth compensation model (schema != {SCHEMA!r})")
    if doc.get("version") != SCHEMA_VERSION:
        raise InputError(
            f"{p}: model version {doc.get('version')!r} is not supported "
            f"(this thermodepth reads version {SCHEMA_VERSION})"
        )
    method = doc.get("method")
    if method not in COMPENSATION_METHODS:
        raise InputError(
            f"{p}: method: unknown {method!r}; expected one of {sorted(COMPENSATION_METHODS)}"
        )
    try:
        return COMPENSATION_METHODS[method].from_dict(doc.get("model", {}))
    except ValidationError as exc:
        raise InputError(f"{p}: model.{describe_validation_error(exc)}") from None
    except ValueError as exc:
        raise InputError(f"{p}: model: {exc}") from None
