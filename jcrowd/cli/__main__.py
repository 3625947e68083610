"""``python -m jcrowd.cli`` runs the command line."""

from jcrowd.cli import main

raise SystemExit(main())
