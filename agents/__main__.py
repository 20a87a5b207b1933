"""``python -m trackenv_agents`` runs the ``trackenv`` command."""

import sys

from .cli import main

sys.exit(main())
