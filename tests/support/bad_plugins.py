"""Plugins that are wrong on purpose, for the plugin manager's error messages."""
from twinkit import hookimpl


def _step(params, ctx, *, out_x_txt):
    out_x_txt.write_text("x")


@hookimpl
def twinkit_register_steps(register):
    register("make", _step)  # clashes with tests.support.engine_plugins' "make"
