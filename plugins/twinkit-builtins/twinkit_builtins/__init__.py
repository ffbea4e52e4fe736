"""Built-in executors and generic steps of twinkit."""
