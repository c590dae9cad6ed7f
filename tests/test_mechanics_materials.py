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
    ("holzapfel-ogden", np.array([0.6, 1.3, 1.0, 3.6, 1.2, 2.0, 0.5, 4.0, 0.2])),  # sheet terms moved, κ = 0.2
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
    np.testing.assert_allclose(v[4:], [0.69, 1.11, 0.31, 2.58, 0.0])  # sheet terms and κ = 0
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


# ----------------------------------------------------------------------------
# fibre dispersion (Gasser-Ogden-Holzapfel κ) and the sheet terms
# ----------------------------------------------------------------------------
def _todays_ho_energy(law, F, frame):
    """The HO law as it was before the dispersion (kept verbatim as the κ = 0 reference)."""
    C = F.T @ F
    f0, s0 = frame[0], frame[1]
    i4f, i4s, i8 = f0 @ C @ f0, s0 @ C @ s0, f0 @ C @ s0
    ef = jnp.where(i4f > 1.0, i4f - 1.0, 0.0)
    es = jnp.where(i4s > 1.0, i4s - 1.0, 0.0)
    i1bar = jnp.linalg.det(F) ** (-2.0 / 3.0) * jnp.trace(C)

    def t(a, b, x):
        return a / (2.0 * b) * jnp.expm1(b * x)

    return (t(law.a, law.b, i1bar - 3.0) + t(law.a_f, law.b_f, ef * ef) + t(law.a_s, law.b_s, es * es)
            + t(law.a_fs, law.b_fs, i8 * i8))


def _random_frame(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q.T  # rows f0, s0, n0: orthonormal


def test_dispersion_zero_is_todays_law_to_round_off():
    """κ = 0 (the default) gives today's energy, stress and tangent (1e-14 relative) on random F and frames."""
    rng = np.random.default_rng(7)
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6})
    assert law.kappa_f == 0.0
    Fs = jnp.asarray(np.eye(3) + 0.2 * rng.normal(size=(40, 3, 3)))
    frames = jnp.asarray(np.stack([_random_frame(rng) for _ in range(40)]))
    for op in (lambda f: f, jax.grad, jax.hessian):
        new = np.asarray(jax.jit(jax.vmap(op(law.strain_energy)))(Fs, frames))
        old = np.asarray(jax.jit(jax.vmap(op(lambda F, fr: _todays_ho_energy(law, F, fr))))(Fs, frames))
        np.testing.assert_allclose(new, old, rtol=1e-14, atol=1e-14 * np.abs(old).max())


def _analytic_ho_stress(p, F, frame):
    """First Piola-Kirchhoff stress of the dispersed HO law written out by hand (kPa)."""
    a, b, af, bf, as_, bs, afs, bfs, kap = p
    C = F.T @ F
    J = np.linalg.det(F)
    Finv_T = np.linalg.inv(F).T
    f0, s0 = frame[0], frame[1]
    i1 = np.trace(C)
    i1bar = J ** (-2 / 3) * i1
    P = a / 2 * np.exp(b * (i1bar - 3)) * J ** (-2 / 3) * (2 * F - 2 / 3 * i1 * Finv_T)
    H = kap * np.eye(3) + (1 - 3 * kap) * np.outer(f0, f0)
    E = np.sum(H * C) - 1
    if E > 0:
        P += 2 * af * E * np.exp(bf * E**2) * F @ H
    i4s = s0 @ C @ s0
    if i4s > 1:
        P += 2 * as_ * (i4s - 1) * np.exp(bs * (i4s - 1) ** 2) * F @ np.outer(s0, s0)
    i8 = f0 @ C @ s0
    P += afs * i8 * np.exp(bfs * i8**2) * F @ (np.outer(f0, s0) + np.outer(s0, f0))
    return P


@pytest.mark.parametrize("kappa", [0.0, 0.1, 0.25, 1 / 3])
def test_dispersed_stress_matches_the_hand_derivation(kappa):
    """Autodiff stress = the hand-written ∂W/∂F (E_f = H:C − 1, H = κI + (1−3κ) f0⊗f0) on random F."""
    rng = np.random.default_rng(3)
    p = np.array([0.6, 1.3, 1.0, 3.6, 0.9, 2.0, 0.4, 3.0, kappa])
    law = materials.HolzapfelOgden.from_vector(p)
    stress = jax.jit(jax.grad(law.strain_energy))  # compiled once: op by op, 0.2-0.35 CPU s a state
    for _ in range(10):
        F = np.eye(3) + 0.15 * rng.normal(size=(3, 3))
        frame = _random_frame(rng)
        P = np.asarray(stress(jnp.asarray(F), jnp.asarray(frame)))
        np.testing.assert_allclose(P, _analytic_ho_stress(p, F, frame), rtol=1e-11, atol=1e-12)


def test_dispersed_fibre_term_uniaxial_analytic():
    """Isochoric stretch λ across the mean fibre: I4f = 1/λ < 1, yet the dispersed family is stretched
    (E_f = κ(λ² + 2/λ − 3) + (1 − 3κ)(1/λ − 1) > 0 for κ = 0.3, λ = 1.2) and contributes; at κ = 0 it does not."""
    lam = 1.2
    F = jnp.diag(jnp.array([lam ** -0.5, lam, lam ** -0.5]))  # fibre along e1, stretch along e2
    frame = np.eye(3)[[0, 2, 1]]  # sheet along e3 (compressed: off)
    base = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "afs": 0.31, "bfs": 2.58}
    i1 = lam**2 + 2 / lam
    matrix = 0.6 / (2 * 1.3) * np.expm1(1.3 * (i1 - 3))
    for kap in (0.0, 0.3):
        W = float(materials.HolzapfelOgden.from_params({**base, "kappa": kap}).strain_energy(F, frame))
        E = kap * (i1 - 3) + (1 - 3 * kap) * (1 / lam - 1)
        fibre = 1.0 / (2 * 3.6) * np.expm1(3.6 * E**2) if E > 0 else 0.0
        assert W == pytest.approx(matrix + fibre, rel=1e-13)
        assert (fibre > 0) == (kap == 0.3)


def test_isotropic_dispersion_does_not_see_the_fibre_direction():
    """κ = 1/3: the fibre family is isotropic (E_f = (I1 − 3)/3); with the sheet terms off the energy
    does not depend on the frame."""
    rng = np.random.default_rng(5)
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 0.0,
                                                "afs": 0.0, "kappa": 1 / 3})
    F = jnp.asarray(np.eye(3) + 0.2 * rng.normal(size=(3, 3)))
    w = [float(law.strain_energy(F, jnp.asarray(_random_frame(rng)))) for _ in range(5)]
    np.testing.assert_allclose(w, w[0], rtol=1e-13)


def test_dispersed_switch_acts_on_the_dispersed_invariant():
    """F = diag(λ, μ, 1/(λμ)), μ = 1.15: at λ = 1 the mean fibre is unstretched (I4f = 1) but I1 > 3, so
    E_f = κ(I1 − 3) > 0 and the fibre family is on; a switch on I4f would make W jump there. W is
    continuous where E_f itself crosses 0."""
    kap, mu = 0.2, 1.15
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 0.0,
                                                "afs": 0.0, "kappa": kap})
    off = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1e-300, "bf": 3.6, "as": 0.0,
                                                "afs": 0.0})
    frame = jnp.eye(3)
    W = jax.jit(jax.vmap(lambda l: law.strain_energy(jnp.diag(jnp.array([l, mu, 1.0 / (l * mu)])), frame)))
    W0 = jax.jit(jax.vmap(lambda l: off.strain_energy(jnp.diag(jnp.array([l, mu, 1.0 / (l * mu)])), frame)))

    def e_f(l):
        i1 = l**2 + mu**2 + 1 / (l * mu) ** 2
        return kap * (i1 - 3) + (1 - 3 * kap) * (l**2 - 1)

    fibre_at_1 = float(W(jnp.array([1.0]))[0] - W0(jnp.array([1.0]))[0])
    assert fibre_at_1 == pytest.approx(1.0 / 7.2 * np.expm1(3.6 * e_f(1.0) ** 2), rel=1e-9) and fibre_at_1 > 1e-5
    from scipy.optimize import brentq

    lstar = brentq(e_f, 0.8, 1.0, xtol=1e-15)
    fib = np.asarray(W(jnp.array([lstar - 1e-3, lstar + 1e-7, lstar + 1e-3]))
                     - W0(jnp.array([lstar - 1e-3, lstar + 1e-7, lstar + 1e-3])))
    assert fib[0] == 0.0 and 0.0 <= fib[1] < 1e-12 and fib[2] > 0  # off below, O(d²) just above: C¹


def test_parameter_ranges():
    HOc = materials.HolzapfelOgden
    assert HOc.parameter_problem("kappa", 0.0) is None and HOc.parameter_problem("kappa", 1 / 3) is None
    assert "[0, 0.333333]" in HOc.parameter_problem("kappa", 0.34)
    assert "[0, 0.333333]" in HOc.parameter_problem("kappa", -0.01)
    assert HOc.parameter_problem("as", 0.0) is None and ">= 0" in HOc.parameter_problem("as", -1.0)
    assert HOc.parameter_problem("afs", 0.0) is None
    assert "> 0" in HOc.parameter_problem("bs", 0.0) and "> 0" in HOc.parameter_problem("a", 0.0)
    assert "finite" in HOc.parameter_problem("bfs", float("nan"))


def test_scaled_law_is_exact_for_unit_factors():
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "kappa": 0.1})
    assert law.scaled(np.ones(9)) == law
    s = law.scale_vector({"a": 2.0, "af": 0.5})
    assert law.scaled(s).params == {**law.params, "a": 1.2, "af": 0.5}
    with pytest.raises(ValueError, match="stiffnesses"):
        law.scale_vector({"b": 2.0})


#: Per constitutive model (kept with it): the compiled automatic derivatives of ``psi`` and the closed-form stress
#: batched over perturbed F. Run op by op, the hessian took 1.2-2 CPU s a state (2026-12-02); compiled once per
#: model, milliseconds.
_COMPILED: dict = {}


def _compiled(model):
    if _COMPILED.get(id(model), (None,))[0] is not model:
        _COMPILED[id(model)] = (model, jax.jit(jax.grad(model.psi)), jax.jit(jax.hessian(model.psi)),
                                jax.jit(jax.vmap(model.first_piola, in_axes=(0, None, None))))
    return _COMPILED[id(model)][1:]


def _assert_closed_form_matches(model, F, Q, p, *, rtol_ad, check_stress_only_path=False):
    """The closed-form stress and tangent at ``(F, Q, p)`` equal the automatic derivatives of ``psi`` (to
    ``rtol_ad``) and the tangent equals central differences of the closed-form stress."""
    grad, hessian, batched_piola = _compiled(model)
    P, A = model.first_piola_tangent(F, Q, p)
    P_ad, A_ad = grad(F, Q, p), hessian(F, Q, p)
    np.testing.assert_allclose(P, P_ad, rtol=rtol_ad, atol=1e-12 * float(jnp.abs(P_ad).max()))
    np.testing.assert_allclose(A, A_ad, rtol=rtol_ad, atol=1e-12 * float(jnp.abs(A_ad).max()))
    if check_stress_only_path:
        np.testing.assert_allclose(model.first_piola(F, Q, p), P, rtol=1e-14, atol=1e-14 * float(jnp.abs(P).max()))
    h = 1e-6
    d = h * np.eye(9).reshape(9, 3, 3)  # d[3k + L] = h e_k e_L^T
    stresses = np.asarray(batched_piola(np.concatenate([F + d, F - d]), Q, p))  # (18, 3, 3): F + d, then F - d
    fd = ((stresses[:9] - stresses[9:]) / (2 * h)).reshape(3, 3, 3, 3).transpose(2, 3, 0, 1)  # fd[i, J, k, L]
    np.testing.assert_allclose(A, fd, rtol=1e-5, atol=1e-6 * float(np.abs(fd).max()))


def _random_states(rng, n):
    """Deformation gradients (J > 0, fibres and sheets in tension and in compression) and orthonormal frames."""
    out = []
    while len(out) < n:
        F = np.eye(3) + 0.25 * rng.normal(size=(3, 3))
        if np.linalg.det(F) < 0.3:
            continue
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        out.append((F, Q, float(rng.normal(scale=2.0))))
    return out


@pytest.mark.parametrize("params", [
    {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
    {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 1.5, "bs": 3.0, "afs": 0.8, "bfs": 4.0, "kappa": 0.15},
    {"a": 2.0, "b": 0.01, "af": 0.3, "bf": 9.0, "as": 0.0, "afs": 0.0, "kappa": 1.0 / 3.0},
])
def test_ho_closed_form_stress_and_tangent_equal_autodiff_and_finite_differences(params):
    """The hand-derived HO stress ``F S + p cof F`` and tangent ``A = ∂P/∂F`` (used by the element kernels)
    equal the automatic derivatives of the energy ``W + p J`` to round-off, and central differences of the
    closed-form stress; tension-switched terms included (states with fibres and sheets on both sides)."""
    law = materials.HolzapfelOgden.from_params(params)
    assert law.closed_form
    model = materials.ConstitutiveModel(law, materials.MixedPenalty(1e3))
    rng = np.random.default_rng(7)
    switched = set()
    for F, Q, p in _random_states(rng, 12):
        _assert_closed_form_matches(model, F, Q, p, rtol_ad=1e-12, check_stress_only_path=True)
        C = F.T @ F
        switched.add((bool(Q[0] @ C @ Q[0] > 1), bool(Q[1] @ C @ Q[1] > 1)))
    assert len(switched) >= 3  # the fibre and sheet switches were met on and off


def test_ho_tangent_at_the_reference_state_takes_the_tension_side_whatever_the_round_off():
    """At F = I the fibre and sheet strains are 0 up to the round-off of F: the closed-form tangent must not
    switch the fibre (sheet) stiffness on or off with that round-off (it decided a cut of the default LV's first
    load step), and takes the tension side: the limit of the tangent at small stretches along the fibre."""
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 1.5, "bs": 3.0})
    model = materials.ConstitutiveModel(law, materials.MixedPenalty(1e3))
    Q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    f0, s0 = Q[0], Q[1]
    tangents = []
    for eps in (1e-15, -1e-15):  # round-off along the fibre and the sheet, both signs
        F = np.eye(3) + eps * (np.outer(f0, f0) + np.outer(s0, s0))
        tangents.append(np.asarray(model.first_piola_tangent(jnp.asarray(F), jnp.asarray(Q), 0.0)[1]))
    np.testing.assert_allclose(tangents[0], tangents[1], rtol=0, atol=1e-10 * np.abs(tangents[0]).max())
    stretched = np.eye(3) + 1e-7 * (np.outer(f0, f0) + np.outer(s0, s0))  # just in tension: both terms on
    A_t = np.asarray(model.first_piola_tangent(jnp.asarray(stretched), jnp.asarray(Q), 0.0)[1])
    np.testing.assert_allclose(tangents[0], A_t, rtol=0, atol=1e-5 * np.abs(A_t).max())
    compressed = np.eye(3) - 1e-7 * (np.outer(f0, f0) + np.outer(s0, s0))  # just in compression: both off
    A_c = np.asarray(model.first_piola_tangent(jnp.asarray(compressed), jnp.asarray(Q), 0.0)[1])
    assert np.abs(A_t - A_c).max() > 0.1 * law.a_f  # the switch is there: the two sides differ


@pytest.mark.parametrize("law", [
    materials.Guccione.from_params({"C": 2.0, "bf": 8.0, "bt": 2.0, "bfs": 4.0}),
    materials.Guccione.from_params({"C": 10.0, "bf": 1.0, "bt": 1.0, "bfs": 1.0}),  # Land et al. problem 2
    materials.NeoHookean.from_params({"mu": 1.5}),
])
def test_isochoric_closed_forms_equal_autodiff_and_finite_differences(law):
    """Guccione (tangent in F-space, stress through the isochoric projection ``tensor_forms.isochoric_split``) and
    neo-Hookean (both through it): stress and tangent equal the automatic derivatives of ``W + p J`` to
    round-off and central differences."""
    assert law.closed_form
    model = materials.ConstitutiveModel(law, materials.MixedPenalty(1e3))
    for F, Q, p in _random_states(np.random.default_rng(11), 6):
        _assert_closed_form_matches(model, F, Q, p, rtol_ad=1e-11)


def test_guccione_f_space_tangent_equals_the_pushed_forward_material_tangent():
    """Guccione's hand-derived F-space tangent (``Guccione.piola_tangent``) equals the push-forward
    ``δ_ik S_JL + F_iI F_kK ℂ_IJKL`` of its material-frame ``pk2_tangent`` (the generic path)."""
    law = materials.Guccione.from_params({"C": 2.0, "bf": 8.0, "bt": 2.0, "bfs": 4.0})
    for F, Q, _ in _random_states(np.random.default_rng(5), 6):
        S, A = law.piola_tangent(jnp.asarray(F), jnp.asarray(Q))
        S0, A0 = materials.MaterialLaw.piola_tangent(law, jnp.asarray(F), jnp.asarray(Q))
        np.testing.assert_allclose(S, S0, rtol=1e-12, atol=1e-13 * float(jnp.abs(S0).max()))
        np.testing.assert_allclose(A, A0, rtol=1e-11, atol=1e-12 * float(jnp.abs(A0).max()))


def test_laws_without_closed_form_use_autodiff(monkeypatch):
    law = materials.Guccione.from_params({"C": 2.0, "bf": 8.0, "bt": 2.0, "bfs": 4.0})
    monkeypatch.setattr(materials.Guccione, "closed_form", False)
    model = materials.ConstitutiveModel(law, materials.MixedPenalty(1e3))
    F, Q, p = _random_states(np.random.default_rng(3), 1)[0]
    P, A = model.first_piola_tangent(F, Q, p)
    np.testing.assert_array_equal(P, jax.grad(model.psi)(F, Q, p))
    np.testing.assert_array_equal(A, jax.hessian(model.psi)(F, Q, p))


@pytest.mark.parametrize("law", [
    materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}),
    materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 1.5, "bs": 3.0,
                                          "afs": 0.8, "bfs": 4.0, "kappa": 0.15}),
    materials.Guccione.from_params({"C": 2.0, "bf": 8.0, "bt": 2.0, "bfs": 4.0}),
    materials.NeoHookean.from_params({"mu": 1.5}),
])
@pytest.mark.parametrize("closed_form", [True, False])
def test_tangent_with_mapped_gradient_slots_equals_the_pulled_back_tangent(law, closed_form, monkeypatch):
    """``first_piola_tangent(F, frame, p, G)`` (what the element kernels ask for, ``G = ∂ξ/∂X``) equals the
    physical tangent with both gradient slots mapped, ``G_KJ A_iJkL G_ML``, to round-off: the laws map the
    3×3 factors of their outer products and the pressure term its cofactors, never the 3⁴ tensor; the
    stress is the physical one. Also through automatic differentiation (``closed_form`` off)."""
    monkeypatch.setattr(type(law), "closed_form", closed_form)
    model = materials.ConstitutiveModel(law, materials.MixedPenalty(1e3))
    rng = np.random.default_rng(17)
    for F, Q, p in _random_states(rng, 6):
        G = rng.normal(size=(3, 3)) + 2.0 * np.eye(3)  # a distorted inverse Jacobian (1/mm)
        P, A = (np.asarray(v) for v in model.first_piola_tangent(jnp.asarray(F), jnp.asarray(Q), p))
        P_m, A_m = (np.asarray(v) for v in model.first_piola_tangent(jnp.asarray(F), jnp.asarray(Q), p,
                                                                        jnp.asarray(G)))
        want = np.einsum("KJ,iJkL,ML->iKkM", G, A, G)
        np.testing.assert_array_equal(P_m, P)
        np.testing.assert_allclose(A_m, want, rtol=1e-11, atol=1e-12 * np.abs(want).max())
        np.testing.assert_array_equal(np.asarray(materials.pull_back(jnp.asarray(A), None)), A)
