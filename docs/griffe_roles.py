"""Griffe extension: the Sphinx roles of slipstep's docstrings (``:class:`Signal```,
``:func:`~slipstep.post.filtering.lowpass```, ``:mod:`slipstep.output.results```) become links of the
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


# `[A] [B]` or `[A][B]` in prose (matrices, vectors: `[dR/dZ  dR/dp] [dZ; dp]`) would be read as a Markdown
# reference link to an identifier B; escape the second bracket unless B is a dotted Python name
NOT_A_LINK = re.compile(r"\](\s?)\[(?![A-Za-z_][\w.]*\])")


def _rewrite(pkg: griffe.Module, obj: griffe.Object) -> None:
    doc = obj.docstring
    if doc is None:
        return
    doc.value = NOT_A_LINK.sub(lambda m: "]" + m.group(1) + "\\[", doc.value)
    if ":`" not in doc.value:
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


class LazyExports(griffe.Extension):
    """The package exports its public names lazily (PEP 562: ``_EXPORTS`` maps a name to its module
    and attribute, ``__getattr__`` imports on first use), which static analysis cannot follow: give
    the package an alias per exported name and the export list, so its API page lists them."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        table = _exports_table(pkg)
        if not table:
            return
        for name, (module, attr) in table.items():
            if name not in pkg.members or pkg.members[name].is_alias:
                pkg.set_member(name, griffe.Alias(name, module if attr is None else f"{module}.{attr}", parent=pkg))
        pkg.exports = list(table)


def _exports_table(pkg: griffe.Module) -> dict[str, tuple[str, str | None]]:
    import ast

    if pkg.filepath is None or isinstance(pkg.filepath, list):
        return {}
    tree = ast.parse(pkg.filepath.read_text())
    for node in tree.body:
        target = getattr(node, "targets", [getattr(node, "target", None)])[0]
        if getattr(target, "id", None) == "_EXPORTS" and node.value is not None:
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                return {}
    return {}
