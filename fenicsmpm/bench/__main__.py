"""python -m fenicsmpm.bench CASE [CASE ...] [--quick] [--out DIR]   (no CASE: all cases)"""
import argparse
import sys

from . import UnknownCaseError, case_names, get_case


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="python -m fenicsmpm.bench",
        description="Run fenicsmpm benchmark cases; each writes DIR/CASE.json, DIR/CASE*.png "
                    "and prints a table.",
        epilog=f"known cases: {', '.join(case_names())}")
    ap.add_argument("cases", nargs="*", metavar="CASE", help="cases to run (default: all)")
    ap.add_argument("--quick", action="store_true",
                    help="scaled-down problems (each case well under a minute)")
    ap.add_argument("--out", default="bench-results", metavar="DIR",
                    help="output directory (default: bench-results/)")
    args = ap.parse_args(argv)
    names = args.cases or case_names()
    try:
        funcs = [get_case(n) for n in names]
    except UnknownCaseError as e:
        ap.error(str(e))
    for fn in funcs:
        fn(quick=args.quick, out=args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
