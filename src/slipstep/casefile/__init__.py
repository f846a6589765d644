"""Case files: where the built-in cases are and reading TOML (``files``), the checks of a case in
the user's terms (``check``), TOML cases <-> model objects (``case``) and assembly cases
(``assembly``). Nothing is imported here, so ``slipstep cases`` stays light."""
