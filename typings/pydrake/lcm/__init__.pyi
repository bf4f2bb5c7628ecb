# Untyped on purpose: typings/README.md.
from typing import Any

def __getattr__(name: str) -> Any: ...
