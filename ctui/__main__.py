import sys

from ctui.cli import main

sys.exit(main())
