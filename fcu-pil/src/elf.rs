//! The firmware image: the loadable segments of the ELF at their load (flash) addresses,
//! exactly what a probe writes to flash, and the symbols the harness needs.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use object::elf::PT_LOAD;
use object::read::elf::{ElfFile32, FileHeader, ProgramHeader};
use object::{Endianness, Object, ObjectSection, ObjectSymbol};

/// Bytes to write at a flash address.
#[derive(Clone, Debug)]
pub struct Segment {
    pub address: u32,
    pub data: Vec<u8>,
}

#[derive(Clone, Debug)]
pub struct Image {
    pub path: PathBuf,
    pub segments: Vec<Segment>,
    /// Word 0 of the vector table.
    pub initial_sp: u32,
    pub symbols: HashMap<String, u32>,
    /// The symbols' sizes in bytes, for the ones that give one (a static's extent in RAM).
    pub symbol_sizes: HashMap<String, u32>,
    /// Functions by address: (start, size, name), sorted, for naming a PC.
    pub functions: Vec<(u32, u32, String)>,
    /// Flash bytes (vector table + text + rodata + data's load image), as `cargo size` adds them.
    pub flash_bytes: u32,
    /// Static RAM (data + bss + uninit).
    pub ram_bytes: u32,
}

impl Image {
    pub fn load(path: &Path) -> Result<Image, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&bytes, path)
    }

    pub fn parse(bytes: &[u8], path: &Path) -> Result<Image, String> {
        let name = path.display();
        let elf = ElfFile32::<Endianness>::parse(bytes).map_err(|e| format!("{name}: not a 32-bit ELF: {e}"))?;
        let endian = elf.endian();
        let header = elf.elf_header();
        if header.e_machine(endian) != object::elf::EM_ARM {
            return Err(format!("{name}: not an ARM ELF"));
        }
        let mut segments = Vec::new();
        for ph in elf.elf_program_headers() {
            if ph.p_type(endian) != PT_LOAD || ph.p_filesz(endian) == 0 {
                continue;
            }
            let data = ph.data(endian, bytes).map_err(|_| format!("{name}: a segment's data is outside the file"))?;
            // The load address (LMA): `.data` runs from RAM but is stored in flash.
            segments.push(Segment { address: ph.p_paddr(endian), data: data.to_vec() });
        }
        let vt = segments
            .iter()
            .find(|s| s.address == crate::machine::FLASH_BASE)
            .ok_or_else(|| format!("{name}: no segment at the start of flash (0x08000000): not a firmware image for this board"))?;
        let initial_sp = vt
            .data
            .get(0..4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| format!("{name}: vector table too short"))?;
        let mut symbols = HashMap::new();
        let mut symbol_sizes = HashMap::new();
        let mut functions = Vec::new();
        for sym in elf.symbols() {
            if let Ok(n) = sym.name() {
                if !n.is_empty() {
                    symbols.insert(n.to_string(), sym.address() as u32);
                    if sym.size() > 0 {
                        symbol_sizes.insert(n.to_string(), sym.size() as u32);
                    }
                    if sym.kind() == object::SymbolKind::Text && sym.size() > 0 {
                        // Thumb functions have bit 0 set in their symbol value.
                        functions.push(((sym.address() as u32) & !1, sym.size() as u32, n.to_string()));
                    }
                }
            }
        }
        functions.sort();
        let mut flash_bytes = 0u32;
        let mut ram_bytes = 0u32;
        for s in elf.sections() {
            let n = s.name().unwrap_or("");
            let size = s.size() as u32;
            match n {
                // memory.x puts the constants in `.rodata.sector0`.
                ".vector_table" | ".text" => flash_bytes += size,
                _ if n.starts_with(".rodata") => flash_bytes += size,
                ".data" => {
                    flash_bytes += size;
                    ram_bytes += size;
                }
                ".bss" | ".uninit" => ram_bytes += size,
                _ => {}
            }
        }
        Ok(Image { path: path.to_path_buf(), segments, initial_sp, symbols, symbol_sizes, functions, flash_bytes, ram_bytes })
    }

    /// The function containing `pc`, its Rust path readable (`fcu_firmware::watchdog::Watchdog::start`).
    pub fn function_at(&self, pc: u32) -> Option<String> {
        let pc = pc & !1;
        let i = self.functions.partition_point(|&(start, _, _)| start <= pc).checked_sub(1)?;
        let (start, size, name) = self.functions.get(i)?;
        (pc < start + size).then(|| demangle(name))
    }

    /// The handler of exception `number` (its vector table entry), as [`Image::function_at`]
    /// names it.
    pub fn handler_name(&self, number: usize) -> Option<String> {
        let vt = self.segments.iter().find(|s| s.address == crate::machine::FLASH_BASE)?;
        let at = number.checked_mul(4)?;
        let word = vt.data.get(at..at + 4)?;
        self.function_at(u32::from_le_bytes(word.try_into().ok()?))
    }

    pub fn symbol(&self, name: &str) -> Option<u32> {
        self.symbols.get(name).copied()
    }

    /// The address and size of the one symbol whose (mangled) name contains `part` and that
    /// gives a size (a static: an RTIC resource's extent in RAM).
    pub fn sized_symbol_containing(&self, part: &str) -> Option<(u32, u32)> {
        let mut found =
            self.symbol_sizes.iter().filter(|(n, _)| n.contains(part)).filter_map(|(n, &size)| Some((*self.symbols.get(n)?, size)));
        let first = found.next()?;
        found.all(|s| s == first).then_some(first)
    }

    /// The address of the one symbol whose (mangled) name contains `part`, e.g.
    /// `rust_begin_unwind` for the panic handler (`__rustc::rust_begin_unwind` in v0 mangling).
    pub fn symbol_containing(&self, part: &str) -> Option<u32> {
        let mut found = self.symbols.iter().filter(|(n, _)| n.contains(part)).map(|(_, &a)| a);
        let first = found.next()?;
        found.all(|a| a == first).then_some(first)
    }
}

/// A legacy-mangled Rust name (`_ZN` + length-prefixed segments + `E`) as a path, without the
/// trailing hash; any other name as it is.
pub fn demangle(name: &str) -> String {
    let Some(mut rest) = name.strip_prefix("_ZN") else {
        return name.to_string();
    };
    let mut parts = Vec::new();
    while let Some(digits) = rest.find(|c: char| !c.is_ascii_digit()).filter(|&d| d > 0) {
        let Ok(len) = rest[..digits].parse::<usize>() else { break };
        let Some(segment) = rest.get(digits..digits + len) else { break };
        parts.push(segment);
        rest = &rest[digits + len..];
    }
    if parts.last().is_some_and(|p| p.len() == 17 && p.starts_with('h')) {
        parts.pop();
    }
    if parts.is_empty() {
        name.to_string()
    } else {
        parts.join("::")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn legacy_names_demangle_to_their_path() {
        assert_eq!(
            super::demangle("_ZN12fcu_firmware8watchdog8Watchdog5start17h0123456789abcdefE"),
            "fcu_firmware::watchdog::Watchdog::start"
        );
        assert_eq!(super::demangle("TIM1_BRK_TIM9"), "TIM1_BRK_TIM9");
    }
}
