"""Allows `python -m smoothjog`."""

from smoothjog.cli import main

raise SystemExit(main())
