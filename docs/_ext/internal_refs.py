"""References in docstrings to this project's objects: checked, even when not documented.

The API reference documents a curated part of the code, while docstrings refer to any of
it (``:func:`ingest.speech.segment.align```) or by another name (``animegraph.synthesize``
is :func:`animegraph.synthesis.synthesize`). A Python reference that Sphinx cannot
resolve links to the documented object it names by another name, or is shown as code,
without a link, if it names an object that exists in ``animegraph``, ``db`` or
``ingest`` (imported to check); otherwise it is left unresolved,
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
from sphinx.util.nodes import make_refnode

PACKAGES = ("animegraph", "db", "ingest")


_MISSING = object()
#: :func:`_documented` of this process' build, made once all pages are read (by identity,
#: so never kept in the saved environment).
_DOCUMENTED: dict = {}


def _lookup(dotted: str):
    """The object ``dotted`` names (a module, or an attribute or annotated field in one),
    else ``_MISSING``; ``None`` for a dataclass field without a default."""
    parts = dotted.split(".")
    if parts[0] not in PACKAGES:
        return _MISSING
    for cut in range(len(parts), 0, -1):
        try:
            obj = import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            if hasattr(obj, name):
                obj = getattr(obj, name)
            elif inspect.isclass(obj) and name == parts[-1] and any(
                    name in getattr(k, "__annotations__", {}) for k in obj.__mro__):
                return None
            else:
                return _MISSING
        return obj
    return _MISSING


def _documented(env) -> dict[int, str]:
    """Documented functions, classes and modules by identity: the name each is
    documented under (``animegraph.synthesize`` is ``animegraph.synthesis.synthesize``)."""
    domain = env.get_domain("py")
    found = {}
    for name, entry in domain.objects.items():
        if entry.objtype in ("function", "class", "exception", "method", "module"):
            obj = _lookup(name)
            if obj is not _MISSING and obj is not None:
                found.setdefault(id(obj), name)
    return found


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
        obj = _lookup(dotted)
        if obj is _MISSING:
            continue
        # Another name of a documented object (a re-export): a link to its page.
        if inspect.isroutine(obj) or inspect.isclass(obj) or inspect.ismodule(obj):
            if _DOCUMENTED.get("env") is not env:
                _DOCUMENTED.update(env=env, names=_documented(env))
            name = _DOCUMENTED["names"].get(id(obj))
            if name is not None:
                entry = env.get_domain("py").objects[name]
                return make_refnode(app.builder, node["refdoc"], entry.docname,
                                    entry.node_id, contnode, name)
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
    app.connect("env-updated", lambda app, env: _DOCUMENTED.clear())
    app.connect("missing-reference", _resolve)
    app.connect("autodoc-skip-member", _skip_members)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
