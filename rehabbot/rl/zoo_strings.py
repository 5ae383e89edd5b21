"""RL Zoo's Python strings in settings files, read without ``eval``:
:func:`parse_python_expression` turns ``"dict(net_arch=[64, 64], activation_fn=nn.ReLU)"`` into
a mapping, accepting only literals, ``dict(...)`` and the torch names of :data:`TORCH_NAMES`
(imported when used)."""

from __future__ import annotations

import ast
import importlib
from typing import Any

# Names a zoo string may use, and the torch classes they stand for.
TORCH_NAMES = {
    **{f"{prefix}{name}": ("torch.nn", name)
       for prefix in ("nn.", "th.nn.", "torch.nn.")
       for name in ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU", "GELU")},
    **{f"{prefix}{name}": ("torch.optim", name)
       for prefix in ("optim.", "th.optim.", "torch.optim.")
       for name in ("Adam", "AdamW", "RMSprop", "SGD")},
}


def parse_python_expression(text: str) -> Any:
    """Evaluate a zoo-style string such as ``"dict(net_arch=[64, 64], activation_fn=nn.ReLU)"``
    without ``eval``: only ``dict(key=value, ...)`` calls, ``{...}`` dicts, lists, tuples,
    numbers, strings, booleans, ``None`` and the torch names of :data:`TORCH_NAMES` are
    accepted.

    Raises:
        ValueError: anything else (names the offending part).
    """
    try:
        tree = ast.parse(str(text).strip(), mode="eval")
    except SyntaxError as err:
        raise ValueError(f"not a valid expression: {text!r} ({err.msg})") from err
    return _literal(tree.body)


def _literal(node: ast.AST) -> Any:
    if isinstance(node, ast.Constant) and (
        node.value is None or isinstance(node.value, (bool, int, float, str))
    ):
        return node.value
    if isinstance(node, ast.List):
        return [_literal(item) for item in node.elts]
    if isinstance(node, ast.Tuple):
        return tuple(_literal(item) for item in node.elts)
    if isinstance(node, ast.Dict) and all(key is not None for key in node.keys):
        return {_literal(key): _literal(value) for key, value in zip(node.keys, node.values,
                                                                      strict=True)}
    if (isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd))
            and isinstance(node.operand, ast.Constant)
            and isinstance(node.operand.value, (int, float))
            and not isinstance(node.operand.value, bool)):
        value = node.operand.value
        return -value if isinstance(node.op, ast.USub) else value
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "dict" and not node.args
            and all(keyword.arg is not None for keyword in node.keywords)):
        return {keyword.arg: _literal(keyword.value) for keyword in node.keywords}
    dotted = ast.unparse(node) if isinstance(node, (ast.Name, ast.Attribute)) else None
    if dotted in TORCH_NAMES:
        return _torch_object(dotted)
    allowed = sorted({name for name in TORCH_NAMES if name.startswith(("nn.", "optim."))})
    raise ValueError(
        f"{ast.unparse(node)!r} is not allowed: only dict(...), literals, lists, tuples and "
        f"the names {', '.join(allowed)}"
    )


def _torch_object(name: str) -> Any:
    module_name, attr = TORCH_NAMES[name]
    return getattr(importlib.import_module(module_name), attr)


def _resolve_torch_names(value: Any) -> Any:
    """Replace strings like ``"nn.ReLU"`` (from a YAML mapping) by the torch classes."""
    if isinstance(value, str) and value.strip() in TORCH_NAMES:
        return _torch_object(value.strip())
    if isinstance(value, dict):
        return {key: _resolve_torch_names(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_resolve_torch_names(item) for item in value]
    return value
