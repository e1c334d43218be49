//! The two parameter sectors of the STM32F401 as the board sees them: 4096 words each, erased
//! to `0xFFFF_FFFF`, programmed a word at a time by clearing bits, and cut off by a power cut at
//! any word.

use fcu_params::snapshot::{ERASED, SECTOR_WORDS};

/// Where a power cut falls: at the `at_word`-th word operation from the moment it was armed (a
/// word programmed counts one, an erase counts one per word of its sector), leaving that word
/// as `partial_bits` says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowerCut {
    pub at_word: u32,
    /// For a program cut short: the bits of the old word that the new one clears but that stay
    /// set (the word is `old & (new | partial_bits)`). For an erase cut short: the bits of the
    /// word the erase reached that are already set again (`old | partial_bits`).
    pub partial_bits: u32,
}

/// The power went off in the middle of a flash operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cut;

/// Two sectors of flash, and a power cut waiting to happen.
#[derive(Clone, Debug)]
pub struct Flash {
    sectors: [Vec<u32>; 2],
    cut: Option<PowerCut>,
    /// Word operations since the cut was armed.
    words_done: u32,
    /// Erases and words programmed since power-on of the bench (wear, and what the checks count).
    pub erases: u32,
    pub words_programmed: u32,
}

impl Default for Flash {
    fn default() -> Self {
        Self::new()
    }
}

impl Flash {
    /// Both sectors erased.
    pub fn new() -> Self {
        Flash {
            sectors: [vec![ERASED; SECTOR_WORDS], vec![ERASED; SECTOR_WORDS]],
            cut: None,
            words_done: 0,
            erases: 0,
            words_programmed: 0,
        }
    }

    /// The sectors as memory-mapped words.
    pub fn sectors(&self) -> [&[u32]; 2] {
        [&self.sectors[0], &self.sectors[1]]
    }

    /// A power cut at a word operation from now on (replacing one armed before).
    pub fn arm_cut(&mut self, cut: PowerCut) {
        self.cut = Some(cut);
        self.words_done = 0;
    }

    /// No power cut waits.
    pub fn disarm_cut(&mut self) {
        self.cut = None;
    }

    /// Counts one word operation; the cut, if this is its word.
    fn step(&mut self) -> Option<PowerCut> {
        let cut = self.cut?;
        if self.words_done == cut.at_word {
            self.cut = None;
            return Some(cut);
        }
        self.words_done = self.words_done.saturating_add(1);
        None
    }

    /// Erases `sector` (0 or 1; another index erases nothing): every word set, in address order,
    /// a power cut leaving the words before it erased, its word partly set and the rest as
    /// they were.
    pub fn erase(&mut self, sector: usize) -> Result<(), Cut> {
        self.erases = self.erases.saturating_add(1);
        for i in 0..SECTOR_WORDS {
            let cut = self.step();
            let Some(word) = self.sectors.get_mut(sector).and_then(|s| s.get_mut(i)) else { return Ok(()) };
            if let Some(cut) = cut {
                *word |= cut.partial_bits;
                return Err(Cut);
            }
            *word = ERASED;
        }
        Ok(())
    }

    /// Programs `words` from word `first` of `sector`, one word at a time: each word becomes
    /// `old & new` (flash only clears bits), a power cut leaving its word with some of the bits
    /// to clear still set and the words after it untouched. Words past the sector's end are
    /// dropped.
    pub fn program(&mut self, sector: usize, first: usize, words: &[u32]) -> Result<(), Cut> {
        for (k, &new) in words.iter().enumerate() {
            let cut = self.step();
            let Some(word) = self.sectors.get_mut(sector).and_then(|s| s.get_mut(first + k)) else { return Ok(()) };
            self.words_programmed = self.words_programmed.saturating_add(1);
            if let Some(cut) = cut {
                *word &= new | cut.partial_bits;
                return Err(Cut);
            }
            *word &= new;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn programming_clears_bits_only_and_a_cut_leaves_the_word_between() {
        let mut f = Flash::new();
        f.program(0, 3, &[0x0F0F_0F0F]).unwrap();
        f.program(0, 3, &[0xFFFF_0000]).unwrap();
        assert_eq!(f.sectors()[0][3], 0x0F0F_0000, "AND of both");
        f.arm_cut(PowerCut { at_word: 1, partial_bits: 0x0000_00F0 });
        assert_eq!(f.program(1, 0, &[0, 0x1234_5600, 7]), Err(Cut));
        assert_eq!(&f.sectors()[1][..3], &[0, 0x1234_56F0, ERASED]);
    }

    #[test]
    fn an_erase_cut_short_leaves_the_sector_partly_erased() {
        let mut f = Flash::new();
        f.program(1, 0, &[0; 8]).unwrap();
        f.arm_cut(PowerCut { at_word: 5, partial_bits: 0x8000_0001 });
        assert_eq!(f.erase(1), Err(Cut));
        assert_eq!(&f.sectors()[1][..8], &[ERASED, ERASED, ERASED, ERASED, ERASED, 0x8000_0001, 0, 0]);
        assert_eq!(f.erase(1), Ok(()));
        assert!(f.sectors()[1].iter().all(|&w| w == ERASED));
    }
}
