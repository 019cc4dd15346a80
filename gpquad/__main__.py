import sys

from gpquad.cli import main

sys.exit(main())
