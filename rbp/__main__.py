from rbp.cli import entry

entry()
