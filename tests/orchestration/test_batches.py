"""flows/common/batches.py: what is added is written exactly once, in order, in batches."""

from flows.common.batches import WriteBatch


def test_batches_by_count_and_on_flush():
    written: list[list[int]] = []
    batch = WriteBatch(written.append, max_items=3, max_wait_s=3600)
    for i in range(7):
        batch.add(i)
    assert written == [[0, 1, 2], [3, 4, 5]]
    batch.flush()
    batch.flush()  # nothing waiting: no empty write
    assert written == [[0, 1, 2], [3, 4, 5], [6]]


def test_an_item_that_waited_long_enough_is_written_at_once():
    written: list[list[str]] = []
    batch = WriteBatch(written.append, max_wait_s=0.0)
    batch.add("a")
    batch.add("b")
    assert written == [["a"], ["b"]]
