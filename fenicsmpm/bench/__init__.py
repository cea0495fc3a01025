"""Benchmark suite: `python -m fenicsmpm.bench CASE [CASE ...] [--quick] [--out DIR]`.

Every case writes DIR/CASE.json (see `common.result` for the schema), at least one
DIR/CASE*.png, and prints a table (rank 0 only under MPI).

Cases live in the dict `CASES` (name -> callable `run(quick=False, out=..., comm=...)`
returning the result dict). A module `fenicsmpm/bench/<name>.py` with a `run` function is
found automatically (underscores in the module name become hyphens: `self_weight.py` is the
case `self-weight`); other code can add one with `register(name, function)`."""
import importlib
import pkgutil

__all__ = ["CASES", "register", "get_case", "case_names", "UnknownCaseError"]

# name -> callable, or "module:function" imported on first use
CASES = {}

_NOT_CASES = {"common", "__main__"}


class UnknownCaseError(KeyError):
    def __str__(self):
        return self.args[0]


def register(name, target):
    """Add a case: target is a callable run(quick=False, out=..., comm=...) -> result dict,
    or a "module:function" string imported on first use."""
    if not (isinstance(name, str) and name):
        raise ValueError(f"bench.register: 'name' must be a non-empty string, got {name!r}")
    if not (callable(target) or (isinstance(target, str) and ":" in target)):
        raise TypeError("bench.register: 'target' must be callable or 'module:function'")
    CASES[name] = target


def _discover():
    for m in pkgutil.iter_modules(__path__):
        if m.name in _NOT_CASES or m.name.startswith("_") or m.ispkg:
            continue
        CASES.setdefault(m.name.replace("_", "-"), f"{__name__}.{m.name}:run")


def case_names():
    """The names of the registered benchmark cases, sorted."""
    return sorted(CASES)


def get_case(name):
    """The run function of a case; UnknownCaseError (listing the known cases) otherwise."""
    target = CASES.get(name)
    if target is None:
        raise UnknownCaseError(f"unknown benchmark case {name!r}; known cases: "
                               f"{', '.join(case_names())}")
    if isinstance(target, str):
        mod, fn = target.split(":")
        target = getattr(importlib.import_module(mod), fn)
        CASES[name] = target
    return target


_discover()
