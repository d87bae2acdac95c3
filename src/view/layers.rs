//! Which of a bundle's transfer layers the viewer shades with: all light,
//! or a chosen set of stored bounces.

use crate::bundle::Transfer;

/// Which transfer layers are summed into the shaded transfer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LayerSelection {
    /// All light: the `Total` layer (or the sum of the stored bounces).
    Total,
    /// The stored bounces whose index is listed (0 = direct); others are off.
    Bounces(Vec<u32>),
}

impl LayerSelection {
    /// Parses `total`, `direct` (bounce 0), `indirect` (bounces ≥ 1) or a
    /// comma list of bounce indices such as `0,2`; `stored` are the bundle's bounce layers.
    pub fn parse(text: &str, stored: &[u32]) -> Result<LayerSelection, String> {
        let missing = || format!("layers {text:?}: the bundle stores no separate bounces (bake with --store-bounces)");
        match text {
            "total" | "all" => Ok(LayerSelection::Total),
            _ if stored.is_empty() => Err(missing()),
            "direct" => Ok(LayerSelection::Bounces(vec![0])),
            "indirect" => Ok(LayerSelection::Bounces(stored.iter().copied().filter(|&b| b > 0).collect())),
            _ => {
                let list = text
                    .split(',')
                    .map(|s| {
                        s.trim().parse::<u32>().map_err(|_| format!("layers {text:?}: expected total, direct, indirect or a list like 0,1"))
                    })
                    .collect::<Result<Vec<u32>, String>>()?;
                match list.iter().find(|b| !stored.contains(b)) {
                    Some(b) => Err(format!("layers {text:?}: bounce {b} is not stored (stored: {stored:?})")),
                    None => Ok(LayerSelection::Bounces(list)),
                }
            }
        }
    }

    /// The summed transfer (vertex-major `[vertex][channel][coeff]`).
    pub fn combine(&self, transfer: &Transfer) -> Vec<f32> {
        match self {
            LayerSelection::Total => transfer.total(),
            LayerSelection::Bounces(list) => transfer.sum_bounces(|b| list.contains(&b)),
        }
    }

    /// Short description for the status line.
    pub fn describe(&self) -> String {
        match self {
            LayerSelection::Total => "total".into(),
            LayerSelection::Bounces(list) if list.is_empty() => "none".into(),
            LayerSelection::Bounces(list) => format!("bounces {list:?}"),
        }
    }
}
