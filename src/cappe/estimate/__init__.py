"""Physical parameter estimation: the common estimator API, parameter spaces with bounded transformations,
the ``cappe.estimate/1`` result, and local uncertainty / identifiability."""

# SPEC 1 lazy loading (scientific-python's lazy_loader): the estimators' modules import scipy.stats, scipy.signal,
# scipy.interpolate and sympy (about 1.3 s); each loads on first use of one of its names, so that e.g. the CLI's
# method registry and its commands without estimation start at once. The names, and their types for type checkers,
# are those imported in __init__.pyi.
import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
