"""The surrogates are scikit-learn estimators: sklearn's own estimator checks pass
(clone, get/set_params, validation of X and y, 1-d and 2-d targets, NaN and sparse refused,
n_features_in_, pickling, fitted-state checks)."""
import pytest
import yaml
from sklearn.neural_network import MLPRegressor
from sklearn.utils.estimator_checks import parametrize_with_checks

from analysis.surrogate.candidates import GPSurrogate, MLPEnsemble, TreeEnsemble
from analysis.surrogate.network import RestartedMLP
from tests.test_config import ROOT

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")

PARAMS = {**yaml.safe_load((ROOT / "config.yaml").read_text())["surrogate"], "hidden_units": 20, "max_iter": 300,
          "n_init": 1}


@parametrize_with_checks([
    RestartedMLP(MLPRegressor(hidden_layer_sizes=(20,), solver="lbfgs", max_iter=300, random_state=0), n_init=2),
    MLPEnsemble(PARAMS, n_members=2),
    GPSurrogate(n_restarts=0),
    TreeEnsemble(n_trees=20),
])
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)
