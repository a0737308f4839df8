"""POST /simulations' body as the OpenAPI document states it: one of a rigid spin, a library scenario or a full
Scenario, and the document and the service (backend.jobs.simulators.validate_scenario) agree on every shape.

Truth: the service's verdict (a body accepted, or refused naming a field) on bodies of each kind, their near misses
(a typo in a key, a missing kind, a wrong type), and the examples the document itself offers.
"""

from __future__ import annotations

from typing import Any

import jsonschema_rs
import pytest
from pydantic import ValidationError

from backend.app import create_app
from backend.jobs.simulators import validate_scenario
from tests.backend.conftest import make_settings

SHAPES = [  # (body, the service accepts it)
    ({"kind": "rigid-spin"}, True),
    ({"kind": "rigid-spin", "duration_s": 5.0, "dt_s": 0.1}, True),
    ({"kind": "rigid-spin", "duraton_s": 5.0}, False),  # a typo: was ignored (a 10 s default run), now named
    ({"kind": "spin"}, False),
    ({"dt_s": 0.1}, False),  # no kind: a Scenario, which has no dt_s
    ({"library": "somov-ge4-scan"}, True),
    ({"library": "somov-ge4-scan", "set": ["duration_s=30"]}, True),
    ({"library": "somov-ge4-scan", "set": "duration_s=30"}, False),
    ({"library": "somov-ge4-scan", "duration_s": 30.0}, False),
    ({"library": 5}, False),
    ({}, True),  # every Scenario field has a default
    ({"duration_s": 30.0, "output_dt_s": 1.0}, True),
    ({"duration_s": "long"}, False),
]


@pytest.fixture(scope="module")
def document(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The app's OpenAPI document (the app is not started: the document needs no lifespan)."""
    tmp_path = tmp_path_factory.mktemp("openapi")
    return create_app(make_settings(tmp_path, f"sqlite:///{tmp_path / 'api.sqlite'}")).openapi()


def _body(document: dict[str, Any]) -> dict[str, Any]:
    return document["paths"]["/api/v1/simulations"]["post"]["requestBody"]["content"]["application/json"]


def _accepted(body: dict[str, Any]) -> bool:
    try:
        validate_scenario(body)
    except (ValidationError, ValueError):
        return False
    return True


def test_the_document_states_the_three_bodies(document: dict[str, Any]) -> None:
    refs = [option["$ref"].rsplit("/", 1)[1] for option in _body(document)["schema"]["oneOf"]]
    assert refs == ["RigidSpinScenario", "LibraryScenario", "Scenario"]
    assert document["components"]["schemas"]["RigidSpinScenario"]["required"] == ["kind"]


@pytest.mark.parametrize(("body", "accepted"), SHAPES)
def test_document_and_service_agree_on_each_shape(document: dict[str, Any], body: dict, accepted: bool) -> None:
    validator = jsonschema_rs.validator_for({**_body(document)["schema"], "components": document["components"]})
    assert _accepted(body) is accepted
    assert validator.is_valid(body) is accepted


def test_the_documents_examples_are_accepted(document: dict[str, Any]) -> None:
    validator = jsonschema_rs.validator_for({**_body(document)["schema"], "components": document["components"]})
    examples = [example["value"] for example in _body(document)["examples"].values()]
    assert len(examples) == 3
    for example in examples:
        assert validator.is_valid(example) and _accepted(example), example


def test_a_typo_in_a_rigid_spin_body_is_named() -> None:
    with pytest.raises(ValidationError) as refused:
        validate_scenario({"kind": "rigid-spin", "duraton_s": 5.0})
    assert refused.value.errors()[0]["loc"] == ("duraton_s",)
