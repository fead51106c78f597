import sys

from shtools.cli.main import main

sys.exit(main())
