"""Material laws: analytic uniaxial energies, autodiff stress vs finite differences, tension-only terms."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lvcore.mechanics import materials

FRAME = np.eye(3)
HO_LAW = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6})
HO = HO_LAW.vector()


def uniaxial(lam):
    return jnp.diag(jnp.array([lam, lam ** -0.5, lam ** -0.5]))


def test_neo_hookean_uniaxial_analytic():
    mu = 3.0
    for lam in (0.8, 1.0, 1.3):
        W = materials.NeoHookean(mu).strain_energy(uniaxial(lam), FRAME)
        assert float(W) == pytest.approx(mu / 2 * (lam**2 + 2 / lam - 3), rel=1e-12, abs=1e-14)


def test_guccione_uniaxial_analytic_and_isochoric():
    C, bf, bt, bfs = 2.0, 8.0, 2.0, 4.0
    p = materials.Guccione(C, bf, bt, bfs)
    lam = 1.2
    E11, E22 = (lam**2 - 1) / 2, (1 / lam - 1) / 2
    Q = bf * E11**2 + bt * 2 * E22**2
    W = p.strain_energy(uniaxial(lam), FRAME)
    assert float(W) == pytest.approx(C / 2 * np.expm1(Q), rel=1e-12)
    # shear in the fibre-sheet plane uses b_fs: F = I + g e1 e2^T (J = 1)
    g = 0.1
    F = jnp.eye(3).at[0, 1].set(g)
    E = 0.5 * (np.array(F).T @ np.array(F) - np.eye(3))
    Q = bf * E[0, 0] ** 2 + bt * (E[1, 1] ** 2) + 2 * bfs * E[0, 1] ** 2
    assert float(p.strain_energy(F, FRAME)) == pytest.approx(C / 2 * np.expm1(Q), rel=1e-12)
    # deviatoric split: a pure dilatation stores no energy
    assert float(p.strain_energy(1.1 * jnp.eye(3), FRAME)) == pytest.approx(0.0, abs=1e-14)


def test_ho_reference_stress_free_and_tension_only():
    grad = jax.grad(HO_LAW.strain_energy)
    assert np.abs(np.asarray(grad(jnp.eye(3), FRAME))).max() < 1e-13
    a, b, af, bf = HO[:4]
    as_, bs = HO[4:6]
    # fibre compressed (I4f < 1): no fibre term; the sheet is stretched (I4s = 1/lam > 1)
    lam = 0.9
    W = HO_LAW.strain_energy(uniaxial(lam), FRAME)
    i1 = lam**2 + 2 / lam
    expect = a / (2 * b) * np.expm1(b * (i1 - 3)) + as_ / (2 * bs) * np.expm1(bs * (1 / lam - 1) ** 2)
    assert float(W) == pytest.approx(expect, rel=1e-12)
    # fibre stretched: the fibre term switches on (sheet compressed stays off)
    lam = 1.1
    W = HO_LAW.strain_energy(uniaxial(lam), FRAME)
    i1 = lam**2 + 2 / lam
    expect = a / (2 * b) * np.expm1(b * (i1 - 3)) + af / (2 * bf) * np.expm1(bf * (lam**2 - 1) ** 2)
    assert float(W) == pytest.approx(expect, rel=1e-12)


@pytest.mark.parametrize("law,params", [
    ("holzapfel-ogden", HO),
    ("guccione", np.array([2.0, 8.0, 2.0, 4.0])),
    ("neo-hookean", np.array([1.5])),
])
def test_autodiff_stress_matches_finite_differences(law, params):
    m = materials.law_class(law).from_vector(params)

    def W(F, frame, params):
        return m.strain_energy(F, frame)

    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.15 * rng.normal(size=(3, 3))
    th = 0.4
    frame = np.array([[np.cos(th), np.sin(th), 0], [-np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    P = np.asarray(jax.grad(W)(jnp.asarray(F), frame, params))
    h = 1e-6
    fd = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            d = np.zeros((3, 3)); d[i, j] = h
            fd[i, j] = (float(W(F + d, frame, params)) - float(W(F - d, frame, params))) / (2 * h)
    np.testing.assert_allclose(P, fd, rtol=1e-6, atol=1e-8)


def test_param_vector_fills_ho_defaults_and_rejects_missing():
    v = materials.HolzapfelOgden.from_params({"a": 1, "b": 2, "af": 3, "bf": 4}).vector()
    np.testing.assert_allclose(v[4:], [0.69, 1.11, 0.31, 2.58])
    with pytest.raises(ValueError, match="needs parameters"):
        materials.Guccione.from_params({"C": 1})
    with pytest.raises(ValueError, match="unknown material law"):
        materials.law_class("mooney-rivlin")


@pytest.mark.parametrize("cls", list(materials.LAWS.values()))
def test_law_registry_round_trips_and_is_a_pytree(cls):
    """One registry: names, parameters, vector and pytree views of each law agree."""
    law = cls.from_params(cls.default_parameters())
    assert materials.LAWS[law.law] is cls and tuple(law.params) == cls.keys
    assert cls.from_vector(law.vector()) == law
    assert set(cls.required) <= set(cls.keys) and set(cls.optional) == set(cls.keys) - set(cls.required)
    leaves, treedef = jax.tree_util.tree_flatten(law)
    assert len(leaves) == len(cls.keys) and jax.tree_util.tree_unflatten(treedef, leaves) == law
    assert law.modulus() == max(law.params[k] for k in cls.stress_keys)


def test_composed_model_jits_once_per_law():
    """Parameters are traced leaves: new values reuse the compiled kernel; another law compiles anew."""
    F = jnp.diag(jnp.array([1.1, 0.95, 0.97]))
    calls = []

    @jax.jit
    def psi(model, F):
        calls.append(1)
        return model.psi(F, FRAME, 0.2)

    def model(law):
        return materials.ConstitutiveModel(law, materials.MixedPenalty(1e3)).as_arrays()

    w1 = psi(model(HO_LAW), F)
    w2 = psi(model(materials.HolzapfelOgden.from_params({"a": 1.2, "b": 1.3, "af": 1.0, "bf": 3.6})), F)
    assert len(calls) == 1 and float(w2) > float(w1)
    psi(model(materials.NeoHookean(1.0)), F)
    assert len(calls) == 2
    expect = HO_LAW.strain_energy(F, FRAME) + 0.2 * np.linalg.det(np.asarray(F))
    assert float(w1) == pytest.approx(float(expect), rel=1e-14)
