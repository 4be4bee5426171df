"""`python -m hbgear ...` -- same as the `hbgear` console script."""

from .cli import console_main

if __name__ == "__main__":
    console_main()
