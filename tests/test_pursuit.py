"""Pursuit records (robot.pursuit): the belief after misses against Bayes' rule written out here, set-aside and
its expiry, release."""
import pytest

from robot.pursuit import Phase, PursuitConfig, Pursuits


def bayes(prior, confirm, k):
    """P(victim there | k close listens, none confirmed): likelihood (1 - confirm)^k if she is there (each listen
    misses her independently), 1 if nobody is there (every listen misses)."""
    there = prior * (1.0 - confirm) ** k
    nobody = (1.0 - prior) * 1.0
    return there / (there + nobody)


@pytest.mark.parametrize("prior, confirm", [(0.9, 0.3), (0.5, 0.6), (0.2, 0.1)])
def test_posterior_after_k_misses_is_bayes_rule(prior, confirm):
    p = Pursuits(PursuitConfig(confirm_probability=confirm))
    for k in range(6):
        assert p.posterior(7, prior) == pytest.approx(bayes(prior, confirm, k), rel=1e-12)
        p.missed(7)
    assert p.of(7).misses == 6 and p.of(7).phase is Phase.CLOSE
    # each miss lowers it; a certain class stays certain; another source is untouched
    assert p.posterior(7, prior) < prior
    assert p.posterior(7, 1.0) == 1.0 and p.posterior(7, 0.0) == 0.0
    assert p.posterior(8, prior) == pytest.approx(prior)


def test_the_fitted_confirm_probability_is_used_unless_configured():
    assert Pursuits(PursuitConfig(), fitted_confirm=0.4).config.confirm_probability == 0.4
    assert Pursuits(PursuitConfig(confirm_probability=0.2), fitted_confirm=0.4).config.confirm_probability == 0.2
    p = Pursuits(PursuitConfig(), fitted_confirm=0.4)
    p.missed(1)
    assert p.posterior(1, 0.5) == pytest.approx(bayes(0.5, 0.4, 1))


def test_set_aside_after_max_contacts_and_back_after_aside_s():
    cfg = PursuitConfig(max_contacts=3, aside_s=60.0)
    p = Pursuits(cfg)
    assert p.available(1, 0.0)
    assert not p.contact(1, 10.0) and not p.contact(1, 11.0)
    assert p.available(1, 11.0)
    assert p.contact(1, 12.0)                              # the third contact sets it aside
    assert p.of(1).phase is Phase.SET_ASIDE
    assert not p.available(1, 12.0) and not p.available(1, 12.0 + 59.9)
    assert p.available(2, 12.0)                            # another source is not affected
    assert p.available(1, 12.0 + 60.0)                     # back after aside_s, counting afresh
    assert p.of(1).phase is Phase.APPROACH and p.of(1).contacts == 0
    assert not p.contact(1, 80.0)


def test_set_aside_after_max_steps_across():
    p = Pursuits(PursuitConfig(max_steps_across=2, aside_s=30.0))
    assert not p.stepped_across(4, 0.0) and not p.stepped_across(4, 1.0)
    assert p.stepped_across(4, 2.0)                         # one more than max_steps_across
    assert not p.available(4, 31.9) and p.available(4, 32.0)
    assert p.of(4).steps_across == 0


def test_release_all_brings_every_set_aside_source_back_and_found_stays_found():
    p = Pursuits(PursuitConfig(max_contacts=1, aside_s=1000.0))
    assert p.contact(1, 0.0) and p.contact(2, 0.0)
    p.found(3)
    assert not p.contact(3, 0.0) and p.of(3).phase is Phase.FOUND     # a found source is never set aside
    p.release_all()
    assert p.available(1, 1.0) and p.available(2, 1.0)
    assert p.of(1).contacts == 0 and p.of(1).phase is Phase.APPROACH
    assert not p.available(3, 1.0) and p.of(3).phase is Phase.FOUND


def test_moved_away_leaves_close_only():
    p = Pursuits(PursuitConfig(confirm_probability=0.3))
    p.missed(1)
    p.moved_away(1)
    assert p.of(1).phase is Phase.APPROACH and p.of(1).misses == 1     # the misses are kept: the belief stays
    p.set_aside(1, 0.0)
    p.moved_away(1)
    assert p.of(1).phase is Phase.SET_ASIDE


@pytest.mark.parametrize("kw, field", [({"confirm_probability": 1.0}, "confirm_probability"),
                                       ({"max_contacts": 0}, "max_contacts"),
                                       ({"max_steps_across": 0}, "max_steps_across"),
                                       ({"aside_s": -1.0}, "aside_s")])
def test_config_errors_name_the_field(kw, field):
    with pytest.raises(ValueError, match=f"PursuitConfig.{field}"):
        PursuitConfig(**kw)


def test_a_miss_does_not_bring_a_set_aside_source_back():
    # Only aside_s (or release_all) ends a set-aside. Fails now: ``missed`` puts any phase to CLOSE, so a source set
    # aside while its estimate lies at the robot's feet (a steep reverberant bearing ranged by the height prior) is
    # available again at the next listen, chosen, and set aside again without a move, cycle after cycle.
    p = Pursuits(PursuitConfig(confirm_probability=0.3, max_steps_across=1, aside_s=60.0))
    p.stepped_across(1, 0.0)
    assert p.stepped_across(1, 1.0)
    p.missed(1)
    assert p.of(1).misses == 1                             # the miss still counts toward the belief
    assert not p.available(1, 2.0) and p.of(1).phase is Phase.SET_ASIDE
