"""What the `sparse-body` command runs (cli.py dispatches to commands/, a module each):
offline make-bag and process, the demo, bench, fuzzing and the reference serial sender. The
top floor: nothing below it (core, estimators, methods, evaluation, train, ros) imports from
here (test_import_graph)."""
