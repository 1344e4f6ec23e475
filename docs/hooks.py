"""mkdocs hook: expand `{{ api jaxvs.<package> }}` into a mkdocstrings block listing every
public name the package exports, so new functions appear in the API reference without
editing the docs (griffe does not treat `from ._x import f as f` re-exports as public)."""

import importlib
import inspect
import re

_MARKER = re.compile(r"^\{\{ api (jaxvs(?:\.[a-z_]+)*) \}\}$", re.M)


def _public(module_name: str) -> list[str]:
    module = importlib.import_module(module_name)
    return [
        name
        for name, obj in vars(module).items()
        if not name.startswith("_") and not inspect.ismodule(obj)
    ]


def on_page_markdown(markdown, page, config, files):
    def expand(match):
        name = match.group(1)
        members = ", ".join(_public(name))
        return f"::: {name}\n    options:\n      members: [{members}]\n"

    return _MARKER.sub(expand, markdown)
