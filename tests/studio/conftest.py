"""The studio's browser tests: the `slow` marker (the slow tier, `scripts/test --all`)."""


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: the slow tier, run by `scripts/test --all` (CI)")
