"""Hostile inputs the tests build: YAML texts that stand for far more than they hold."""


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """A YAML flow sequence of ``levels`` anchors, each ``width`` aliases of the one before: a
    few hundred bytes that stand for width ** levels (3.9e8) values."""
    parts = ['&a0 [' + ', '.join(['x'] * width) + ']']
    parts += [f'&a{k} [' + ', '.join([f'*a{k - 1}'] * width) + ']' for k in range(1, levels)]
    return '[' + ', '.join(parts) + ']'


def deep(levels: int = 5000) -> str:
    """A YAML sequence nested ``levels`` deep."""
    return '[' * levels + ']' * levels
