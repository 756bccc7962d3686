"""``python -m cli``: the ``recon`` command without its console script (as ``python -m recon``)."""

import sys

from cli.main import main

sys.exit(main())
