"""``python -m fieldcal ...``: the ``fieldcal`` command."""

from .cli import main

if __name__ == "__main__":
    main()
