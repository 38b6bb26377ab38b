from .default_parameters import (
    ML_DSA_44,
    ML_DSA_65,
    ML_DSA_87,
    HASH_ML_DSA_44_WITH_SHA512,
    HASH_ML_DSA_65_WITH_SHA512,
    HASH_ML_DSA_87_WITH_SHA512,
)

__all__ = [
    "ML_DSA_44",
    "ML_DSA_65",
    "ML_DSA_87",
    "HASH_ML_DSA_44_WITH_SHA512",
    "HASH_ML_DSA_65_WITH_SHA512",
    "HASH_ML_DSA_87_WITH_SHA512",
]
