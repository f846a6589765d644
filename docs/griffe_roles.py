"""Griffe extension: the Sphinx roles of slipstep's docstrings (``:class:`Signal```,
``:func:`~slipstep.post.filtering.lowpass```, ``:mod:`slipstep.results```) become links of the
API reference, resolved like Sphinx does: an absolute path, else a name of the object's class or
module, else of the package; a name that resolves to nothing (a private helper) stays code.
"""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|mod|data|meth|attr|exc|obj|const):`([^`]+)`")


def _lookup(pkg: griffe.Module, path: str):
    if path == pkg.path:
        return pkg
    if not path.startswith(pkg.path + "."):
        return None
    try:
        return pkg[path[len(pkg.path) + 1 :]]
    except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None


def _resolve(pkg: griffe.Module, obj: griffe.Object, target: str) -> str | None:
    scopes = []
    scope = obj
    while scope is not None:
        scopes.append(scope.path)
        scope = scope.parent
    for base in ["", *scopes]:
        path = f"{base}.{target}" if base else target
        found = _lookup(pkg, path)
        if found is None or found.name.startswith("_"):
            continue
        if not found.is_alias:
            return found.path
        # an imported name: link to where it is defined, if that is in the package (it is documented there)
        target = found.target_path
        if not target.startswith(pkg.path + ".") or _lookup(pkg, target) is None:
            return None
        return target
    return None


def _rewrite(pkg: griffe.Module, obj: griffe.Object) -> None:
    doc = obj.docstring
    if doc is None or ":`" not in doc.value:
        return

    def replace(match: re.Match) -> str:
        text = match.group(1).strip()
        short = text.startswith("~")
        target = text.lstrip("~").lstrip(".")
        label = target.rsplit(".", 1)[-1] if short else target
        path = _resolve(pkg, obj, target)
        return f"[`{label}`][{path}]" if path else f"`{label}`"

    doc.value = ROLE.sub(replace, doc.value)


def _walk(pkg: griffe.Module, obj: griffe.Object) -> None:
    _rewrite(pkg, obj)
    for member in obj.members.values():
        if not member.is_alias:
            _walk(pkg, member)


class SphinxRoles(griffe.Extension):
    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        _walk(pkg, pkg)
