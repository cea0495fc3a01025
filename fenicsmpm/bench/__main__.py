"""python -m fenicsmpm.bench CASE [CASE ...] [--quick] [--out DIR] [case options]
(no CASE: all cases)

A case module may define add_arguments(parser) for options of its own (e.g. mpi-scaling's
--ranks and --weak); they are offered when that case is asked for and passed to its run
function by name."""
import argparse
import sys

from . import UnknownCaseError, case_names, get_case


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="python -m fenicsmpm.bench",
        description="Run fenicsmpm benchmark cases; each writes DIR/CASE.json, DIR/CASE*.png "
                    "and prints a table.",
        epilog=f"known cases: {', '.join(case_names())}", add_help=False)
    ap.add_argument("cases", nargs="*", metavar="CASE", help="cases to run (default: all)")
    ap.add_argument("--quick", action="store_true",
                    help="scaled-down problems (each case well under a minute)")
    ap.add_argument("--out", default="bench-results", metavar="DIR",
                    help="output directory (default: bench-results/)")
    known, _ = ap.parse_known_args(argv)
    names = known.cases or case_names()
    try:
        funcs = [get_case(n) for n in names]
    except UnknownCaseError as e:
        ap.error(str(e))
    options = []                       # per case: the destinations of its own options
    for name, fn in zip(names, funcs):
        add = getattr(sys.modules.get(fn.__module__), "add_arguments", None)
        dests = []
        if add is not None:
            group = ap.add_argument_group(f"options of {name}")
            add(group)
            dests = [a.dest for a in group._group_actions]
        options.append(dests)
    ap.add_argument("-h", "--help", action="help", help="show this help message and exit")
    args = ap.parse_args(argv)
    for fn, dests in zip(funcs, options):
        fn(quick=args.quick, out=args.out, **{d: getattr(args, d) for d in dests})
    return 0


if __name__ == "__main__":
    sys.exit(main())
