"""Modules that moved: their old import path keeps working for one release, with a warning.

`alias_moved_modules(moved, removed_in)` installs an import hook that answers an old module path
(`import dpc_mjx.robots.base_file`, `from dpc_mjx.robots import base_file`, `from
dpc_mjx.robots.base_file import read_base`) with the module at its new path, the same module
object, after one `DeprecationWarning` that names the new path and the release the old one goes
away in. No file stays behind at the old path (no twin to keep in step), and nothing is imported
before someone asks for the old path.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old paths of `moved` ({old dotted path: new dotted path}) and loads each as the
    module at its new path."""

    def __init__(self, moved: dict[str, str], removed_in: str):
        self.moved, self.removed_in = dict(moved), removed_in
        self._specs: dict[str, importlib.machinery.ModuleSpec] = {}  # old path -> new's spec

    def find_spec(self, fullname, path=None, target=None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in self.moved:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        new = self.moved[spec.name]
        warnings.warn(
            f"{spec.name} moved to {new}; import it from there (the old path goes away in "
            f"dpc_mjx {self.removed_in}).",
            DeprecationWarning,
            stacklevel=2,
        )
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        # The import system set the old path's spec on the module it got: give it its own back,
        # so that the module is the same object, with the same name and spec, under both paths.
        module.__spec__ = self._specs[module.__spec__.name]


def alias_moved_modules(moved: dict[str, str], removed_in: str) -> None:
    """Let each old module path of `moved` ({old: new}, full dotted paths) import the module at
    its new path, warning once (`DeprecationWarning`) that it moved and goes away in dpc_mjx
    `removed_in`."""
    if not any(isinstance(f, _MovedModules) and f.moved == moved for f in sys.meta_path):
        sys.meta_path.append(_MovedModules(moved, removed_in))


__all__ = ["alias_moved_modules"]
