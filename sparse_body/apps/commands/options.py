"""`sparse-body options`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations


def run(args) -> int:
    from ...methods import METHODS
    from .. import option_docs

    if args.markdown:
        print(option_docs.markdown(), end="")
    else:
        print("\n\n".join(option_docs.text(m) for m in ([args.method] if args.method else METHODS)))
    return 0


def add_parser(sub) -> None:
    from ...methods import METHODS

    p = sub.add_parser("options", help="every option of a method: type, default, range and what it does")
    p.add_argument("method", nargs="?", choices=list(METHODS), help="the method (default: all)")
    p.add_argument("--markdown", action="store_true", help="the table of docs/options.md, for every method")
    p.set_defaults(func=run)
