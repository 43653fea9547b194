"""The top folder of a clrays checkout, which Python imports as `clrays` when it starts in
the folder above (the working directory comes first on sys.path, and a folder of this name
there wins over the installed package). Without this file that import made a namespace
package of the checkout: `import clrays` passed and `clrays.render` was an AttributeError.
It hands the import on to the package inside, so `import clrays` reads as it does anywhere.
"""
import importlib.util
import sys
from pathlib import Path

_package = Path(__file__).resolve().parent / "clrays"
_spec = importlib.util.spec_from_file_location(__name__, _package / "__init__.py",
                                               submodule_search_locations=[str(_package)])
_module = importlib.util.module_from_spec(_spec)
sys.modules[__name__] = _module  # the import returns what sys.modules holds once this file has run
_spec.loader.exec_module(_module)
