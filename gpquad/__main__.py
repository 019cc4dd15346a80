from gpquad.cli.commands import entry

entry()
