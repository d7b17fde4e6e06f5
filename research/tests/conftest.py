"""Helpers of the research tests: the product tests' own (repository root, real data, camera pools)."""

from tests.conftest import REPO, SHARED_DATA, random_pool, shared_data

__all__ = ["REPO", "SHARED_DATA", "random_pool", "shared_data"]
