import sys

from zbuf_occlude.cli.main import main

sys.exit(main())
