"""The `rbp` sub-commands that have a module of their own (`rbp.cli` holds the parser and the
small ones), and what they share (`common`). Heavy modules are imported inside each handler,
so importing these keeps `rbp --help` instant."""
