"""The identification engine: variables, numba kernels, expression trees, coevolution."""
