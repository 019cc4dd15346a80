import sys

from gpquad.cli.commands import main

sys.exit(main())
