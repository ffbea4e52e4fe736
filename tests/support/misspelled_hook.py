"""A plugin whose hook name is misspelled: loading must fail loudly."""
from twinkit import hookimpl


@hookimpl
def twinkit_register_step(register):  # missing "s"
    pass
