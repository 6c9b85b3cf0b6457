"""``python -m accal.cli`` (as ``python -m accal``, without its signal handling)."""

from accal.cli import main

main()
