"""References in docstrings to this project's objects: checked, even when not documented.

The API reference documents a curated part of the code, while docstrings refer to any of
it (``:func:`ingest.speech.segment.align```). A Python reference that Sphinx cannot
resolve is shown as code, without a link, if it names an object that exists in
``animegraph``, ``db`` or ``ingest`` (imported to check); otherwise it is left unresolved,
and ``nitpicky`` (docs/conf.py) makes that a warning: a docstring naming a function that
was renamed or removed fails the build.

Also leaves out of class pages the methods scikit-learn generates on every estimator
(``set_fit_request`` and the like, whose docstrings point into scikit-learn's own
documentation) and bare data attributes (the Attributes section says what they are).
"""

from __future__ import annotations

import inspect
from importlib import import_module

from docutils import nodes
from sphinx.application import Sphinx

PACKAGES = ("animegraph", "db", "ingest")


def _lookup(dotted: str) -> bool:
    """True if ``dotted`` names a module, or an attribute (or annotated field) in one."""
    parts = dotted.split(".")
    if parts[0] not in PACKAGES:
        return False
    for cut in range(len(parts), 0, -1):
        try:
            obj = import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            if hasattr(obj, name):
                obj = getattr(obj, name)
            elif inspect.isclass(obj) and any(
                    name in getattr(k, "__annotations__", {}) for k in obj.__mro__):
                return name == parts[-1]  # a dataclass field without a default
            else:
                return False
        return True
    return False


def _candidates(target: str, module: str | None, cls: str | None) -> list[str]:
    """Where ``target`` may live, as Python name resolution in a docstring sees it."""
    target = target.lstrip(".~")
    found = [target]
    if module:
        scopes = [f"{module}.{cls}"] if cls else []
        parts = module.split(".")
        scopes += [".".join(parts[:i]) for i in range(len(parts), 0, -1)]
        found += [f"{scope}.{target}" for scope in scopes]
    return found


def _resolve(app: Sphinx, env, node: nodes.Element, contnode: nodes.Element):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    for dotted in _candidates(target, node.get("py:module"), node.get("py:class")):
        if _lookup(dotted):
            return contnode
    return None


def _skip_members(app, what, name, obj, skip, options):
    if what != "class":
        return None
    # scikit-learn's metadata-routing methods (set_fit_request ...), made for each class.
    if name.startswith("set_") and name.endswith("_request"):
        return True
    # Data attributes (dataclass fields: ``obj`` is their default value, or autodoc's
    # marker without one): the class's numpydoc Attributes section describes them, the
    # signature gives their defaults; listed again they would be bare names.
    if not (callable(obj) or inspect.isdatadescriptor(obj)
            or isinstance(obj, (classmethod, staticmethod))):
        return True
    return None


def setup(app: Sphinx) -> dict:
    app.connect("missing-reference", _resolve)
    app.connect("autodoc-skip-member", _skip_members)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
