"""How the tests are laid out, and the one setting every test run needs.

Layout: the folders mirror the package. A file lives in the folder of the
``leosop`` package whose code it mainly tests (``tests/fusion/test_engine.py``
tests ``leosop/fusion/engine.py``); the top-level modules (frames, earth,
timebase, rotations, ...) are tested in ``tests/base/``. A file whose subject
is a command - it drives ``leosop <command>`` through ``leosop.cli.main`` and
checks the command's contract: JSON keys, exit codes, output files, bad-input
messages - lives in ``tests/cli/``, named after the command; a file whose
subject is a library module stays with that module even when it makes its
inputs with the command line. Two folders mirror no package:
``tests/hardening/`` holds the hostile-input suites of issue 13 that span the
readers of several packages (hypothesis properties, the fuzz corpus, hostile
files), and ``tests/project/`` the repository-wide checks (lint, types,
layers, the docs and their site, the gallery, the install, tools/).

Imports: every folder is a package (an ``__init__.py``), so pytest's default
import mode puts the repository on ``sys.path`` and names each module from
there (``tests.fusion.test_engine``): the same basename may sit in two
folders, and ``python -m pytest``, ``python -m pytest tests/fusion`` and a
single file import alike. Helpers shared by several packages' tests are in
``tests/helpers.py``, those of one folder in its ``helpers.py``
(``from tests.fusion.helpers import STEP``); fixtures are in the folder's
``conftest.py``. No test module imports another test module, and none
imports a conftest (pytest loads those itself).
"""

import os

# As the CLI does (leosop/cli/__init__.py): the filters' many small matrix products are several times slower
# under a multi-threaded BLAS on a busy machine. It acts only if numpy is not imported yet (pytest does not).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
