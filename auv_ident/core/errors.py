"""Error types of the core. Each message names the culprit (file, key, row, value)."""


class AuvIdentError(Exception):
    """Base class of every error auv_ident raises on purpose."""


class ConfigError(AuvIdentError, ValueError):
    """A vehicle file, a parameter or an option is wrong (names the key and the value)."""


class DimensionError(AuvIdentError, ValueError):
    """An array has the wrong shape."""


class DomainError(AuvIdentError, ArithmeticError):
    """A state or input lies outside the model's domain (u ~ 0, complex epsilon, theta ~ 90 deg,
    NaN/Inf); evaluating the model there would give NaN or a complex number."""


class DivergenceError(AuvIdentError, ArithmeticError):
    """The filter lost positive definiteness or its estimate became non-finite."""


class DataError(AuvIdentError, ValueError):
    """The data cannot be used as given (sample times not increasing, NaN stamps, ...)."""
