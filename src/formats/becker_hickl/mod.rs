//! Becker & Hickl files: FIFO photon files (`.spc`, [`spc`]), histogram
//! files (`.sdt`, [`sdt`]) and the setup text SPCM writes beside and into
//! them ([`setup`]). The layouts follow B&H's own description of its files
//! (`SPC_data_file_structure.h`, shipped with SPCM), as independent readers
//! quote it (sdtfile, tttrlib, libtcspc).

pub mod sdt;
pub mod setup;
pub mod spc;
