"""What a user installs with thermodepth (MIT): no GPL package among its dependencies or
extras, read from each installed package's own metadata."""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

tomllib = pytest.importorskip("tomllib", reason="pyproject.toml is read with Python 3.11's tomllib")

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def gpl(meta: metadata.PackageMetadata) -> str | None:
    """What says a package is under the GPL or AGPL (not the LGPL), or None."""
    expression = meta.get("License-Expression") or ""
    if re.search(r"\bA?GPL", expression):  # SPDX: GPL-3.0-or-later, AGPL-3.0; not LGPL-3.0
        return f"License-Expression: {expression}"
    for classifier in meta.get_all("Classifier") or []:
        if re.search(r"GNU (Affero )?General Public License", classifier):
            return classifier
    text = " ".join((meta.get("License") or "")[:200].upper().split())
    if re.search(r"GNU (AFFERO )?GENERAL PUBLIC LICENSE", text):
        return f"License: {text[:60]}"
    return None


def test_no_dependency_or_extra_is_gpl() -> None:
    project = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]
    wanted = [("dependencies", r) for r in project["dependencies"]] + [
        (f"extra {extra}", r)
        for extra, reqs in project["optional-dependencies"].items()
        for r in reqs
    ]
    checked, found = 0, []
    for where, requirement in wanted:
        name = Requirement(requirement).name
        try:
            meta = metadata.metadata(name)
        except metadata.PackageNotFoundError:
            continue  # not installed here: its licence cannot be read from its metadata
        checked += 1
        why = gpl(meta)
        if why:
            found.append(f"{name} ({where}): {why}")
    assert checked >= len(project["dependencies"])  # at least the core ones were read
    assert not found, "GPL packages: " + "; ".join(found)


def test_the_licence_test_tells_gpl_from_lgpl() -> None:
    def meta(**fields: str) -> metadata.PackageMetadata:
        from email.message import Message

        m = Message()
        for k, v in fields.items():
            m[k.replace("_", "-")] = v
        return m  # type: ignore[return-value]

    assert gpl(meta(License_Expression="GPL-3.0-or-later"))
    assert gpl(meta(License_Expression="MIT OR AGPL-3.0-only"))
    assert gpl(meta(Classifier="License :: OSI Approved :: GNU General Public License v3 (GPLv3)"))
    assert gpl(meta(License="GNU GENERAL PUBLIC LICENSE\n   Version 3, 29 June 2007"))
    assert not gpl(meta(License_Expression="LGPL-3.0-or-later"))
    assert not gpl(
        meta(Classifier="License :: OSI Approved :: GNU Lesser General Public License v3 (LGPLv3)")
    )
    assert not gpl(meta(License="GNU LESSER GENERAL PUBLIC LICENSE"))
    assert not gpl(meta(License_Expression="MIT", License="MIT"))
