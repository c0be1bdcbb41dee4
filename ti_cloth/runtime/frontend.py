"""Taichi's Python front end, kept from doing the same work again for every call of a ti.func.

Before Taichi compiles a kernel, its Python front end walks the kernel's syntax tree and every
ti.func inlined into it, and for each call of a ti.func reads that function's source again
(inspect, which searches sys.modules and re-tokenizes the file), and for each name and
expression builds a debug location: the source line with carets under the expression,
re-wrapped by textwrap at 80 columns. A ti_cloth step inlines the same ti.funcs hundreds of
times, so on the cape (demos/cape.toml) this was about half of the front end's time, and
with the offline cache warm (a scene run again: Taichi still runs the front end to find the
cached kernel) the front end is most of a build: 10-11 s of its first step against 5-7 s
with the two memos below (docs/performance.md, "Taichi's front end").

`install()` (backend.init calls it) memoises both, for Taichi 1.7 (pyproject.toml pins it):

- the source of a function (`getsourcelines`, `getsourcefile` as kernel_impl imported them),
  by the function object, weakly: Taichi's own answer the first time, the same afterwards;
- a debug location (`ASTTransformerContext.get_pos_info`), keyed by everything it reads: the
  file, the function's name and line offset and indentation, the node's type and span, and
  the source lines it quotes. The same key gives the same text: Taichi's message is a pure
  function of those.

Neither changes what Taichi compiles or the text of any of its messages (tests/test_frontend.py
compares every location of a Fabric step's kernels with Taichi's own). `TI_CLOTH_TAICHI_MEMO=0`
in the environment leaves Taichi as it is (a check, and benchmarks/build_time.py's baseline).
A Taichi whose front end does not have these names is left as it is.
"""

from __future__ import annotations

import os
import weakref

SWITCH = "TI_CLOTH_TAICHI_MEMO"      # "0": leave Taichi's front end as it is
MULTILINE = ("For", "While", "FunctionDef", "If")   # get_pos_info quotes their head only
MOST_LOCATIONS = 200_000    # memoised locations kept at most (ti_cloth's step: about 10,000)

_installed = False
_originals: dict = {}
_locations: dict = {}


def install() -> bool:
    """Memoise Taichi's source reads and debug locations (module doc), once per process;
    whether they are memoised."""
    global _installed
    if _installed:
        return True
    if os.environ.get(SWITCH, "1") == "0":
        return False
    try:
        from taichi.lang import kernel_impl
        from taichi.lang.ast import ast_transformer_utils
        context = ast_transformer_utils.ASTTransformerContext
        originals = {"getsourcelines": kernel_impl.getsourcelines,
                     "getsourcefile": kernel_impl.getsourcefile,
                     "get_pos_info": context.get_pos_info}
    except (ImportError, AttributeError):       # another Taichi: leave it as it is
        return False
    _originals.update(originals)
    kernel_impl.getsourcelines = _by_function(originals["getsourcelines"])
    kernel_impl.getsourcefile = _by_function(originals["getsourcefile"])
    context.get_pos_info = _location
    _installed = True
    return True


def installed() -> bool:
    """Whether install() has memoised Taichi's front end in this process."""
    return _installed


def original(name: str):
    """Taichi's own function `name` ("getsourcelines", "getsourcefile", "get_pos_info")
    that install() memoised."""
    return _originals[name]


def location_count() -> int:
    """How many distinct debug locations are memoised."""
    return len(_locations)


def _by_function(read):
    """read(function), memoised by the function (weakly: a function dropped drops its
    entry; an object that takes no weak reference is read every time)."""
    memo = weakref.WeakKeyDictionary()

    def memoised(function):
        try:
            return memo[function]
        except KeyError:
            found = memo[function] = read(function)
            return found
        except TypeError:
            return read(function)

    return memoised


def _location(context, node):
    """Taichi's get_pos_info(node) in `context`, memoised (module doc)."""
    head = type(node).__name__
    end = node.end_lineno
    if head in MULTILINE and end != node.lineno:
        end = max(node.body[0].lineno - 1, node.lineno)
    key = (context.file, context.func.func.__name__, context.lineno_offset, context.indent,
           head, node.lineno, node.col_offset, node.end_lineno, node.end_col_offset,
           tuple(context.src[node.lineno - 1:max(end, node.lineno)]))
    found = _locations.get(key)
    if found is None:
        if len(_locations) >= MOST_LOCATIONS:   # kernels defined again and again (a notebook)
            _locations.clear()
        found = _locations[key] = _originals["get_pos_info"](context, node)
    return found
