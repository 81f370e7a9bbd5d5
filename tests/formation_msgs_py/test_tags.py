"""The run's tag (issue 28 item 2): HMAC-SHA256 over payload, topic, writer and sequence; the key
file; what a reader with and without the key refuses."""

import os
import stat

import pytest

from formation_msgs_py import tags
from formation_msgs_py.errors import KeyFileError, TagError
from formation_msgs_py.tags import FORGED, REPLAYED, UNTAGGED, Signer, Verifier

KEY = bytes(range(32))
OTHER = bytes(range(1, 33))
TOPIC = '/agent_2/trigger_info/to_1'
VALUES = (1.0, 1.0, 2.0, 1.0, 0.25, 2.0, 0.5, -0.5, 1.0, 2.0)


def _refusal(verifier: Verifier, topic: str, values, tag) -> str | None:
    try:
        verifier.check_array(topic, values, tag)
    except TagError as error:
        return error.reason
    return None


def test_the_mac_is_hmac_sha256_of_the_documented_bytes():
    """Computed here from the module docstring's layout, not by the module's own helper."""
    import hashlib
    import hmac
    import struct

    payload = struct.pack('<10d', *VALUES)
    message = b'formation-tag-1\0' + TOPIC.encode() + b'\0agent_2\0' + struct.pack('>Q', 7) + payload
    expected = hmac.new(KEY, message, hashlib.sha256).hexdigest()
    assert tags.array_payload(VALUES) == payload
    assert tags.tag_text(KEY, topic=TOPIC, writer='agent_2', sequence=7, payload=payload) == (
        f'tag1:agent_2:7:{expected}'
    )


def test_a_signed_message_passes_once_and_a_copy_is_a_replay():
    signer, verifier = Signer(KEY, writer='agent_2'), Verifier(KEY)
    first, second = signer.tag_array(TOPIC, VALUES), signer.tag_array(TOPIC, VALUES)
    assert first != second  # the sequence differs
    assert _refusal(verifier, TOPIC, VALUES, first) is None
    assert _refusal(verifier, TOPIC, VALUES, second) is None
    assert _refusal(verifier, TOPIC, VALUES, first) == REPLAYED
    assert verifier.refused == {UNTAGGED: 0, FORGED: 0, REPLAYED: 1} and verifier.foreign == 0


@pytest.mark.parametrize(
    ('change', 'reason'),
    [
        (lambda tag, values, topic: (None, values, topic), UNTAGGED),
        (lambda tag, values, topic: (tag, (*values[:-1], 2.5), topic), FORGED),  # a value changed
        (lambda tag, values, topic: (tag, values, '/agent_3/trigger_info/to_1'), FORGED),  # another topic
        (lambda tag, values, topic: (tag.replace(':1:', ':9:'), values, topic), FORGED),  # its sequence
        (lambda tag, values, topic: (tag.replace('agent_2', 'agent_3'), values, topic), FORGED),  # its writer
        (lambda tag, values, topic: (tag[:-1], values, topic), FORGED),  # not 64 hex digits
        (lambda tag, values, topic: ('tag1:junk', values, topic), FORGED),
        (
            lambda tag, values, topic: (
                Signer(OTHER, writer='agent_2').tag_array(topic, values),
                values,
                topic,
            ),
            FORGED,
        ),  # another run's key
    ],
)
def test_a_message_without_the_run_keys_tag_is_refused_as_foreign(change, reason):
    tag = Signer(KEY, writer='agent_2').tag_array(TOPIC, VALUES)
    verifier = Verifier(KEY)
    got_tag, values, topic = change(tag, VALUES, TOPIC)
    assert _refusal(verifier, topic, values, got_tag) == reason
    assert verifier.foreign == 1
    # The refusal leaves the writer's sequence alone: its real first message still passes.
    assert _refusal(verifier, TOPIC, VALUES, tag) is None


def test_a_reader_without_a_key_takes_everything():
    verifier = Verifier(None)
    assert not verifier.required
    assert _refusal(verifier, TOPIC, VALUES, None) is None
    assert _refusal(verifier, TOPIC, VALUES, 'tag1:junk') is None
    assert verifier.check_string('/formation/agent_report', '{"a":1}') == '{"a":1}'


def test_a_tagged_string_keeps_its_text_and_its_tag_line_is_checked():
    signer, verifier = Signer(KEY, writer='agent_1'), Verifier(KEY)
    text = '{"version":3,"agent":1}'
    tagged = signer.tag_string('/formation/agent_report', text)
    assert tagged.startswith(text + '\ntag1:agent_1:1:')
    assert tags.split_text(tagged) == (text, tagged.split('\n')[1])
    assert tags.split_text(text) == (text, None)
    assert verifier.check_string('/formation/agent_report', tagged) == text
    with pytest.raises(TagError, match='without the run') as caught:
        verifier.check_string('/formation/agent_report', text)
    assert caught.value.reason == UNTAGGED
    with pytest.raises(TagError) as caught:
        verifier.check_string('/formation/agent_report', tagged.replace('"agent":1', '"agent":2'))
    assert caught.value.reason == FORGED


def test_the_key_file_is_private_new_and_checked(tmp_path):
    path = tmp_path / tags.KEY_FILE
    key = tags.new_key()
    assert len(key) == tags.KEY_BYTES and tags.new_key() != key
    tags.write_key(path, key)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert tags.read_key(path) == key
    with pytest.raises(KeyFileError, match='a key file exists already'):
        tags.write_key(path, tags.new_key())
    assert tags.read_key(path) == key  # never overwritten
    os.chmod(path, 0o644)
    with pytest.raises(KeyFileError, match=r'readable by its owner only \(mode 0600\), got 0644'):
        tags.read_key(path)
    short = tmp_path / 'short.key'
    tags.write_key(tmp_path / 'ok.key', key)
    fd = os.open(short, os.O_WRONLY | os.O_CREAT, 0o600)
    os.write(fd, b'abcd\n')
    os.close(fd)
    with pytest.raises(KeyFileError, match='must hold 32 bytes as hex, got 2 bytes'):
        tags.read_key(short)
    with pytest.raises(KeyFileError, match='cannot be read'):
        tags.read_key(tmp_path / 'missing.key')
    with pytest.raises(KeyFileError, match='has 32 bytes, got 3'):
        tags.write_key(tmp_path / 'bad.key', b'abc')


def test_a_writer_name_cannot_break_the_tags_fields():
    with pytest.raises(ValueError, match='no ":" or newline'):
        Signer(KEY, writer='agent:2')


def test_a_tagged_array_keeps_its_data_and_layout_and_its_decoders_read_it_as_before():
    from formation_msgs_py.codec import array_tag, check_array, decode_step, encode_step, tag_array
    from formation_msgs_py.lockstep import Step

    step = Step(index=4, time=0.125, flags=0, epoch=0.0, due=(1, 3))
    plain, tagged = (
        encode_step(step),
        tag_array(encode_step(step), Signer(KEY, writer='keeper'), '/formation/step'),
    )
    assert array_tag(plain) is None and array_tag(tagged).startswith('tag1:keeper:1:')
    assert list(tagged.data) == list(plain.data)
    assert [d.label for d in tagged.layout.dim[:-1]] == [d.label for d in plain.layout.dim]
    assert (tagged.layout.dim[-1].size, tagged.layout.dim[-1].stride) == (0, 0)
    assert [d.label for d in encode_step(step).layout.dim] == [
        d.label for d in plain.layout.dim
    ]  # shared layout
    assert decode_step(tagged) == decode_step(plain) == step
    verifier = Verifier(KEY)
    check_array(verifier, '/formation/step', tagged)
    with pytest.raises(TagError) as caught:
        check_array(verifier, '/formation/step', plain)
    assert caught.value.reason == UNTAGGED
    check_array(Verifier(None), '/formation/step', plain)  # no key: nothing checked


def test_a_tagged_report_decodes_as_the_untagged_one():
    from formation_msgs_py.codec import check_string, decode_agent_report, encode_agent_report, tag_string
    from formation_msgs_py.lockstep import AgentReport

    report = AgentReport(agent=2, final=True, rejected={'untagged': 1}, dropped=0)
    tagged = tag_string(encode_agent_report(report), Signer(KEY, writer='agent_2'), '/formation/agent_report')
    assert decode_agent_report(tagged) == decode_agent_report(encode_agent_report(report)) == report
    check_string(Verifier(KEY), '/formation/agent_report', tagged)
    with pytest.raises(TagError) as caught:
        check_string(Verifier(KEY), '/formation/status', tagged)  # another topic's tag
    assert caught.value.reason == FORGED


def test_a_reader_that_names_the_writer_refuses_the_runs_tag_from_another():
    key = bytes(range(32))
    verifier = Verifier(key)
    own, other = Signer(key, writer='agent_2'), Signer(key, writer='agent_3')
    verifier.check('/agent_2/sense', b'sense', own.tag('/agent_2/sense', b'sense'), writer='agent_2')
    with pytest.raises(TagError, match="from 'agent_3', where only 'agent_2' may write") as caught:
        verifier.check('/agent_2/sense', b'sense', other.tag('/agent_2/sense', b'sense'), writer='agent_2')
    assert caught.value.reason == FORGED and verifier.refused[FORGED] == 1
