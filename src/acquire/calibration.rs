//! Time zero: the micro-time offset of the instrument (cables, laser
//! trigger, electronics) measured with a reference, e.g. the laser pointed
//! at the sensor through no scattering medium. t0 is the centre of the most
//! populated micro-time step of that reference recording.

use std::path::Path;

use firmware_protocol::record::Record;

use super::pipeline::AcquireError;
use crate::formats::sstags::read_tag_file;

/// t0 in picoseconds from a raw tag file of a reference measurement.
pub fn t0_from_reference(path: &Path) -> Result<f64, AcquireError> {
    let mut hist: Vec<u64> = Vec::new();
    let summary = read_tag_file(path, |batch| {
        for raw in batch.raw_records() {
            if let Ok(Record::Photon { micro, .. }) = Record::decode(raw) {
                let m = micro as usize;
                if m >= hist.len() {
                    hist.resize(m + 1, 0);
                }
                hist[m] += 1;
            }
        }
    })
    .map_err(AcquireError::TagFile)?;
    let Some((peak, _)) = hist
        .iter()
        .enumerate()
        .filter(|(_, c)| **c > 0)
        .max_by_key(|(_, c)| **c)
    else {
        return Err(AcquireError::Plan(format!(
            "{}: the reference recording holds no photons, so it gives no t0",
            path.display()
        )));
    };
    let res_ps = f64::from(summary.header.resolution_fs) / 1000.0;
    Ok((peak as f64 + 0.5) * res_ps)
}
