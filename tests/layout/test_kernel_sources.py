"""Facts written once in the kernel sources: a number a kernel file defines is defined in
that file only; the ones several files share come from clrays/structs.py (`-D`)."""
from __future__ import annotations

import re

from clrays import structs
from clrays.device import kernel_dir

NUMERIC_DEFINE = re.compile(r"^\s*#\s*define\s+(\w+)\s+\(?\s*[-+]?(?:0x[0-9a-fA-F]+|\d|\.\d)", re.M)


def test_no_number_is_defined_in_two_kernel_files():
    files_of = {}
    for path in sorted(kernel_dir().glob("*.[ch]*")):
        for name in set(NUMERIC_DEFINE.findall(path.read_text())):
            files_of.setdefault(name, []).append(path.name)
    assert {name: files for name, files in files_of.items() if len(files) > 1} == {}


def test_no_kernel_file_defines_a_shared_constant():
    defined = {name for path in kernel_dir().glob("*.[ch]*") for name in NUMERIC_DEFINE.findall(path.read_text())}
    assert defined & set(structs.KERNEL_CONSTANTS) == set()
