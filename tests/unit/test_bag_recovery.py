"""Reading unfinished MCAP bags: ``flush_writer`` + ``recover_mcap`` (no ROS needed).

The truth is what the test wrote: a bag cut at any byte (a killed recorder, a full disk)
reads back as a prefix of the written messages, complete up to the last flushed chunk.
"""
import shutil

import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from adcs_nodes.bag import flush_writer, make_typestore, read_messages, recover_mcap

N = 60
FLUSH_EVERY = 10


@pytest.fixture(scope='module')
def unfinished(tmp_path_factory):
    """An open bag with N messages, flushed every FLUSH_EVERY, copied while still open."""
    tmp = tmp_path_factory.mktemp('bags')
    store = make_typestore()
    string = store.types['std_msgs/msg/String']
    writer = Writer(tmp / 'bag', version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=store)
    for i in range(N):
        raw = store.serialize_cdr(string(data=f'm{i}'), 'std_msgs/msg/String')
        writer.write(conn, 1_000 + i, raw)
        if (i + 1) % FLUSH_EVERY == 0 and i + 1 < N:
            assert flush_writer(writer, fsync=(i + 1) == FLUSH_EVERY)
    shutil.copytree(tmp / 'bag', tmp / 'killed')   # what a SIGKILL leaves on disk
    writer.close()
    return tmp / 'killed' / 'bag.mcap', tmp / 'bag'


def _data(path):
    return [msg.data for _, _, msg in read_messages(path)]


def test_unfinished_bag_holds_every_flushed_message(unfinished):
    mcap, finished = unfinished
    assert not (mcap.parent / 'metadata.yaml').exists()
    assert _data(mcap.parent) == [f'm{i}' for i in range(N - FLUSH_EVERY)]
    assert _data(finished) == [f'm{i}' for i in range(N)]   # unchanged for a closed bag


def test_a_cut_anywhere_reads_back_as_a_prefix(unfinished, tmp_path):
    mcap, _ = unfinished
    raw = mcap.read_bytes()
    sent = [f'm{i}' for i in range(N)]
    counts = []
    for cut in sorted(set(range(0, len(raw), max(1, len(raw) // 37))) | {len(raw)}):
        path = tmp_path / f'cut{cut}.mcap'
        path.write_bytes(raw[:cut])
        try:
            got = _data(path)
        except ValueError as exc:   # nothing complete yet: a clear message, no traceback
            assert cut < 200, (cut, exc)
            assert 'empty file' in str(exc) or 'not an MCAP file' in str(exc), exc
            counts.append(0)
            continue
        assert got == sent[:len(got)], cut
        assert len(got) % FLUSH_EVERY == 0, (cut, len(got))   # whole chunks only
        counts.append(len(got))
    assert counts == sorted(counts)
    assert counts[-1] == N - FLUSH_EVERY


def test_garbage_and_empty_files_are_errors(tmp_path):
    empty = tmp_path / 'empty.mcap'
    empty.write_bytes(b'')
    with pytest.raises(ValueError, match='wrote nothing'):
        recover_mcap(empty, tmp_path / 'out1.mcap')
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 64)
    with pytest.raises(ValueError, match='not an MCAP file'):
        recover_mcap(garbage, tmp_path / 'out2.mcap')
    text = tmp_path / 'text.mcap'
    text.write_text('hello')
    with pytest.raises(ValueError, match='not an MCAP file'):
        recover_mcap(text, tmp_path / 'out3.mcap')
