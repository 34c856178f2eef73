import sys

from crowdstudy.cli import main

sys.exit(main())
