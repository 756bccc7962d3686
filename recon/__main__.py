"""``python -m recon``: the ``recon`` command without its console script (the one module of
``recon`` allowed to import ``cli``)."""

import sys

from cli.main import main

sys.exit(main())
