"""Optional dependencies: a feature and the extra it needs -> nothing, or one ``MissingExtraError`` line (exit 4).

The base install (pyproject.toml) holds matplotlib, casadi, cvxpy, networkx and scipy; ``dask`` (Dask
distributed: ``--dask``) and ``testing`` (hypothesis: ``tubempc.strategies``, the falsifier's ``targeted`` search)
are extras. ``report`` (matplotlib: report.html and its figures) and ``plan`` (casadi, cvxpy, networkx, scipy: plan,
simulate, falsify, regress, demo) name the parts of the base a command needs, so that an install missing one of them
gets a line saying what to reinstall; ``all`` is every one of them. Each place that needs an extra calls ``require``
before importing it, so a missing one is one line naming the extra to install, never an ImportError traceback.
"""

from __future__ import annotations

import importlib.util
import sys

from runkit.errors import MissingExtraError

__all__ = ["EXTRAS", "missing_modules", "require"]

#: extra -> the modules it installs (the import names)
EXTRAS: dict[str, tuple[str, ...]] = {
    "report": ("matplotlib",),
    "dask": ("dask", "distributed"),
    "testing": ("hypothesis",),
    "plan": ("casadi", "cvxpy", "networkx", "scipy"),
}


def _importable(name: str) -> bool:
    if name in sys.modules:
        return sys.modules[name] is not None  # None: an import of it was blocked
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def missing_modules(extra: str) -> list[str]:
    """The modules of ``extra`` that cannot be imported (empty: the extra is installed)."""
    if extra not in EXTRAS:
        raise ValueError(f"extra={extra!r} is not one of {', '.join(EXTRAS)}")
    return [name for name in EXTRAS[extra] if not _importable(name)]


def require(*extras: str, feature: str, alternative: str | None = None) -> None:
    """Raise ``MissingExtraError`` when ``feature`` cannot run because a module of one of ``extras`` is not
    installed; the message names every extra it lacks (and ``alternative``, a way to do without, if any)."""
    lacking = [extra for extra in extras if missing_modules(extra)]
    if not lacking:
        return
    missing = [name for extra in lacking for name in missing_modules(extra)]
    verb = "is" if len(missing) == 1 else "are"
    which = f"the '{lacking[0]}' extra" if len(lacking) == 1 else \
        "the " + " and ".join(f"'{e}'" for e in lacking) + " extras"
    spec = ",".join(lacking)
    other = f", or {alternative}" if alternative else ""
    raise MissingExtraError(f"{feature} needs {', '.join(missing)}, which {verb} not installed: install {which} "
                            f"(pip install 'tubempc[{spec}]'; from a clone: pip install -e '.[{spec}]'){other}")
