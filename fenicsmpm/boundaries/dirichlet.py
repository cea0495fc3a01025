"""Dirichlet conditions: a geometric locator plus components, resolved to a dof mask."""
import numpy as np


def fixed_dofs(grid, where, components):
    """Boolean mask (n_nodes, gdim) of the dofs fixed by where(x) on the given components.

    where(x) takes node coordinates of shape (n, gdim) and returns one bool per node.
    Raises ValueError if the locator matches no node anywhere (on any rank)."""
    if not callable(where):
        raise TypeError(f"fix: 'where' must be callable where(x) -> bool, got {type(where).__name__}")
    comps = list(range(grid.gdim)) if components is None else list(np.atleast_1d(components))
    for c in comps:
        if not (isinstance(c, (int, np.integer)) and 0 <= c < grid.gdim):
            raise ValueError(f"fix: 'components' must be integers in [0, {grid.gdim}), got {components!r}")
    nodes = grid.nodes_where(where)
    if grid.global_count(nodes[: grid.n_owned_nodes]) == 0:
        raise ValueError("fix: the Dirichlet locator 'where' matches no grid node")
    mask = np.zeros((grid.n_nodes, grid.gdim), dtype=bool)
    mask[np.ix_(nodes, comps)] = True
    return mask
