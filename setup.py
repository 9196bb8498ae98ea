"""The optional compiled data path (vstig_hw._vstig): everything else is in pyproject.toml.

The extension is libvstig (firmware_spec/libvstig, the protocol in C that robots link) plus the
glue in vstig_hw/_cext, with every table at 32,768 places (every key). It is optional: where
nothing compiles (no C compiler, no Python headers) the build says so and the install goes on
with the pure-Python path, which is the reference anyway (DECISIONS.md, "The gateway's compiled
data path").
"""

import os
from pathlib import Path

from setuptools import Extension, setup

LIBVSTIG = Path("firmware_spec") / "libvstig"
GLUE = Path("vstig_hw") / "_cext"

setup(
    ext_modules=[
        Extension(
            "vstig_hw._vstig",
            sources=sorted(str(p) for p in (*GLUE.glob("*.c"), *LIBVSTIG.glob("vstig_*.c"))),
            depends=sorted(str(p) for p in (*GLUE.glob("*.h"), *LIBVSTIG.glob("*.h"))),
            include_dirs=[str(LIBVSTIG), str(GLUE)],
            # the gateway's tables hold every key: never full, one comparison a lookup
            define_macros=[("VSTIG_KEYS", "32768u"), ("VSTIG_QUEUE", "32768u"), ("VSTIG_GUARD_KEYS", "32768u"),
                           ("VSTIG_WRITER_KEYS", "1024u")],
            extra_compile_args=["-O2"],
            # VSTIG_BUILD_NATIVE=1 (make test does): a compile error fails the install instead of leaving it pure
            optional=os.environ.get("VSTIG_BUILD_NATIVE") != "1",
        ),
    ],
)
