//! The bounded transmit queue: whole frames in, any number of bytes out.

/// A byte ring of `N` bytes. A frame goes in whole or not at all, so the UART never sends
/// half a frame; the caller drains it at its own pace with [`TxQueue::pop`].
#[derive(Clone, Debug)]
pub struct TxQueue<const N: usize> {
    buf: [u8; N],
    head: usize,
    len: usize,
}

impl<const N: usize> Default for TxQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TxQueue<N> {
    /// An empty queue.
    pub const fn new() -> Self {
        Self { buf: [0; N], head: 0, len: 0 }
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Nothing waiting.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Room left, in bytes.
    pub fn free(&self) -> usize {
        N - self.len
    }

    /// Appends a whole frame; false (and nothing written) when it does not fit.
    pub fn push(&mut self, frame: &[u8]) -> bool {
        if frame.len() > self.free() {
            return false;
        }
        for &byte in frame {
            let at = wrap::<N>(self.head + self.len);
            if let Some(slot) = self.buf.get_mut(at) {
                *slot = byte;
            }
            self.len += 1;
        }
        true
    }

    /// Moves up to `out.len()` waiting bytes into `out`; returns how many.
    pub fn pop(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in out.iter_mut() {
            if self.len == 0 {
                break;
            }
            if let Some(&byte) = self.buf.get(self.head) {
                *slot = byte;
            }
            self.head = wrap::<N>(self.head + 1);
            self.len -= 1;
            n += 1;
        }
        n
    }
}

/// `at` modulo `N` for `at < 2 N` (a head plus a length), without a division.
fn wrap<const N: usize>(at: usize) -> usize {
    if at >= N {
        at - N
    } else {
        at
    }
}
