"""`python -m clrays`: the command line."""
from clrays.cli import main

if __name__ == "__main__":
    main()
