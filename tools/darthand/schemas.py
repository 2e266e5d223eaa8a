"""The project's JSON contracts (schemas/*.schema.json): loading a schema and checking a document against it with a
one-line error naming the file and field."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import jsonschema

from darthand.errors import InputError
from darthand.fileio import field_key, first_non_finite, read_json

SCHEMA_DIR = Path(__file__).resolve().parents[2] / "schemas"


@functools.cache
def load_schema(name: str) -> dict:
    """The parsed schemas/<name>."""
    return json.loads((SCHEMA_DIR / name).read_text())


@functools.cache
def _validator(name: str) -> jsonschema.protocols.Validator:
    return jsonschema.Draft202012Validator(load_schema(name))


def check_schema(doc, name: str, source: str) -> None:
    """Raise InputError '<source>: field '<path>' <message>' for the most relevant violation of schemas/<name>, or
    for a NaN or infinite number anywhere in `doc` (a dict given through the API may hold them)."""
    bad = first_non_finite(doc)
    if bad:     # JSON has no NaN or Infinity, and a schema's bounds do not catch NaN (every comparison is false)
        raise InputError(f"{source}: field '{bad}' is not a finite number")
    validator = _validator(name)
    if validator.is_valid(doc):       # the common case, without collecting errors
        return
    error = jsonschema.exceptions.best_match(validator.iter_errors(doc))
    if error is None:
        return
    where = ".".join(field_key(p) for p in error.absolute_path) or "(top level)"
    message = error.message if len(error.message) <= 160 else error.message[:157] + "..."
    raise InputError(f"{source}: field '{where}' {message}")


def read_catalog(path, what: str, schema: str) -> tuple[Path, dict]:
    """A stage's catalogue, given as its file or its folder (catalog.json inside): (the file, its contents checked
    against schemas/<schema>); InputError naming the file and field."""
    path = Path(path)
    path = path / "catalog.json" if path.is_dir() else path
    data = read_json(path, f"{what} catalogue (build it with the {what} stage)")
    check_schema(data, schema, str(path))
    return path, data


def check_unique_ids(items: list, source: str, field: str = "items") -> None:
    """InputError '<source>: field '<field>.<i>.id' repeats id ...' for the first item whose 'id' an earlier one has."""
    seen: set = set()
    for i, item in enumerate(items):
        if item["id"] in seen:
            raise InputError(f"{source}: field '{field}.{i}.id' repeats id {item['id']!r}")
        seen.add(item["id"])
