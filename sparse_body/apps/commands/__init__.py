"""The `sparse-body` commands, a module each (add_parser, run); cli.py lists and dispatches them."""
