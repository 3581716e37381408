"""What the `sparse-body` command runs (cli.py parses and dispatches): evaluation, offline
make-bag and process, the demo, bench, fuzzing and the reference serial sender. Nothing in the
runtime (core, estimators, ros) imports from here."""
