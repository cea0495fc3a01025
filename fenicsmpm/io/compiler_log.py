"""Quiet form compilation: FFCx compiles each new UFL form (tractions, Robin and absorbing
boundaries, frictional bases with mesh normals) with cffi, which logs "running build_ext" and
the gcc command lines as INFO records on the root logger while it raises the root level for
the build, so they reach stderr through any root handler. `import fenicsmpm` installs
`CompilerFilter` on the root logger, which drops those records (and sets the "ffcx" and "cffi"
loggers to WARNING if nobody set their level).

To see the compiler's output, ask for it:
    import logging
    logging.getLogger("fenicsmpm.compiler").setLevel(logging.INFO)
Warnings and errors of the build always pass."""
import logging

LOGGER = "fenicsmpm.compiler"
_BUILD_MODULES = ("distutils", "setuptools", "cffi")


class CompilerFilter(logging.Filter):
    """Drops records below WARNING that the build tools (distutils, setuptools, cffi) log on
    the root logger, unless the "fenicsmpm.compiler" logger's own level is INFO or lower."""

    def filter(self, record):
        if record.levelno >= logging.WARNING:
            return True
        level = logging.getLogger(LOGGER).level
        if level and level <= record.levelno:
            return True
        path = record.pathname.replace("\\", "/")
        return not any(f"/{m}/" in path or f"/_{m}/" in path for m in _BUILD_MODULES)


def silence_compiler_output():
    """Install CompilerFilter on the root logger (once) and set the "ffcx" and "cffi" loggers
    to WARNING when their level is unset. Called by `import fenicsmpm`."""
    root = logging.getLogger()
    if not any(isinstance(f, CompilerFilter) for f in root.filters):
        root.addFilter(CompilerFilter())
    for name in ("ffcx", "cffi"):
        lg = logging.getLogger(name)
        if lg.level == logging.NOTSET:
            lg.setLevel(logging.WARNING)
