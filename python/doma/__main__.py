"""The ``doma`` command line from the Python package (``pip install`` puts it on the PATH as
``doma``; ``python -m doma`` runs it too): the Rust binary's own CLI, run in process."""

import os
import sys


def main() -> int:
    """Runs ``doma`` with this process's arguments and returns its exit status."""
    # As the binary does first (doma::backend::pin_default_device): Burn's default device
    # is the CPU, so that resuming a CPU fit never needs a GPU adapter. Set here, before
    # the extension starts a thread.
    os.environ.setdefault("BURN_DEVICE", "flex")
    from . import _native

    return _native.main(["doma", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
