//! The roller followers: how many, how they are sprung, preload, roller radius and friction.
//!
//! Everything the pitch curve needs from the followers reduces to the effective rate `k_eff`
//! in dU/dY = k_eff*(Y + Yp) (docs/THEORY.md, "Virtual work"), the preload Yp, and the contact friction
//! coefficient with the chosen friction correction.

use serde::Serialize;

/// Effective friction coefficients at or above this are refused (phi = 45 deg).
pub const MAX_FRICTION: f64 = 1.0;

/// How the follower springs are arranged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpringArrangement {
    /// Each follower has its own spring of rate ks: k_eff = count * ks.
    PerFollower,
    /// Two opposed followers joined by one spring of rate ks, stretched by 2Y: k_eff = 4 * ks.
    Shared,
}

/// Where the contact friction coefficient comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FrictionSource {
    /// An effective contact coefficient given directly.
    Coefficient {
        /// The coefficient.
        coefficient: f64,
    },
    /// A roller turning on a pin: mu_eff = pin_friction * r_pin / r_roller + rolling / r_roller.
    Pin {
        /// Friction coefficient of the pin (plain bearing) or bearing.
        pin_friction: f64,
        /// Pin radius.
        pin_radius_mm: f64,
        /// Rolling resistance lever arm.
        rolling_resistance_mm: f64,
    },
}

/// Which stroke the cam is corrected for, so that its force follows the law exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FrictionCorrection {
    /// The loading stroke (x increasing) follows the law; unloading is lower.
    Loading,
    /// The unloading stroke follows the law; loading is higher.
    Unloading,
    /// The mean of loading and unloading follows the law.
    Midline,
    /// The frictionless pitch curve; friction shows as hysteresis on both sides.
    None,
}

impl std::fmt::Display for SpringArrangement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SpringArrangement::PerFollower => "per-follower",
            SpringArrangement::Shared => "shared",
        })
    }
}

impl std::fmt::Display for FrictionCorrection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FrictionCorrection::Loading => "loading",
            FrictionCorrection::Unloading => "unloading",
            FrictionCorrection::Midline => "midline",
            FrictionCorrection::None => "none",
        })
    }
}

/// The follower arrangement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Follower {
    /// Number of followers on opposed cam surfaces (1 or 2).
    pub count: u8,
    /// Spring arrangement.
    pub arrangement: SpringArrangement,
    /// Rate ks of each physical spring.
    pub spring_rate_n_per_mm: f64,
    /// Initial compression Yp, as follower displacement.
    pub preload_mm: f64,
    /// Roller radius r.
    pub roller_radius_mm: f64,
    /// Contact friction.
    pub friction: FrictionSource,
    /// Which stroke the pitch curve is corrected for.
    pub friction_correction: FrictionCorrection,
    /// The roller's bearing and duty, for the life check (all optional).
    pub bearing: RollerBearing,
}

/// A roller's bearing and its duty: what the L10 life check needs.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RollerBearing {
    /// Basic dynamic load rating C of the roller's bearing (ISO 281), N.
    pub dynamic_load_n: Option<f64>,
    /// Strokes (load and return) the transmission must survive.
    pub duty_strokes: Option<f64>,
    /// Strokes per second in use (for the roller speed), Hz.
    pub stroke_rate_hz: Option<f64>,
}

impl Follower {
    /// One follower with its own spring of rate `spring_rate_n_per_mm` and a roller of radius
    /// `roller_radius_mm`: no preload, no friction, loading correction. Change the rest with
    /// the `with_*` methods.
    pub fn new(spring_rate_n_per_mm: f64, roller_radius_mm: f64) -> Follower {
        Follower {
            count: 1,
            arrangement: SpringArrangement::PerFollower,
            spring_rate_n_per_mm,
            preload_mm: 0.0,
            roller_radius_mm,
            friction: FrictionSource::Coefficient { coefficient: 0.0 },
            friction_correction: FrictionCorrection::Loading,
            bearing: RollerBearing::default(),
        }
    }

    /// A copy with `count` followers on opposed cam surfaces (1 or 2).
    pub fn with_count(&self, count: u8) -> Follower {
        Follower { count, ..*self }
    }

    /// A copy with another spring arrangement.
    pub fn with_arrangement(&self, arrangement: SpringArrangement) -> Follower {
        Follower {
            arrangement,
            ..*self
        }
    }

    /// A copy with another roller radius.
    pub fn with_roller_radius(&self, roller_radius_mm: f64) -> Follower {
        Follower {
            roller_radius_mm,
            ..*self
        }
    }

    /// A copy with another contact friction.
    pub fn with_friction(&self, friction: FrictionSource) -> Follower {
        Follower { friction, ..*self }
    }

    /// A copy corrected for another stroke.
    pub fn with_friction_correction(&self, friction_correction: FrictionCorrection) -> Follower {
        Follower {
            friction_correction,
            ..*self
        }
    }

    /// The physical springs: how many, and how far one is deflected when every follower has
    /// risen by `y_mm` (its force is the rate times this). Per-follower springs are compressed
    /// by Y + Yp; one spring shared by two opposed followers is stretched by 2 (Y + Yp).
    pub fn springs(&self, y_mm: f64) -> (u8, f64) {
        match self.arrangement {
            SpringArrangement::PerFollower => (self.count, y_mm + self.preload_mm),
            SpringArrangement::Shared => (1, 2.0 * (y_mm + self.preload_mm)),
        }
    }

    /// k_eff in dU/dY = k_eff*(Y + Yp).
    pub fn k_eff_n_per_mm(&self) -> f64 {
        match self.arrangement {
            SpringArrangement::PerFollower => f64::from(self.count) * self.spring_rate_n_per_mm,
            SpringArrangement::Shared => 4.0 * self.spring_rate_n_per_mm,
        }
    }

    /// Total follower spring force q = k_eff*(Y + Yp) at follower lift `y_mm`.
    pub fn spring_force_n(&self, y_mm: f64) -> f64 {
        self.k_eff_n_per_mm() * (y_mm + self.preload_mm)
    }

    /// The force pressing one roller onto its cam surface (along Y) at lift `y_mm`: q / count.
    pub fn spring_force_per_roller_n(&self, y_mm: f64) -> f64 {
        self.spring_force_n(y_mm) / f64::from(self.count)
    }

    /// Effective contact friction coefficient.
    pub fn friction_coefficient(&self) -> f64 {
        match self.friction {
            FrictionSource::Coefficient { coefficient } => coefficient,
            FrictionSource::Pin {
                pin_friction,
                pin_radius_mm,
                rolling_resistance_mm,
            } => {
                if self.roller_radius_mm > 0.0 {
                    (pin_friction * pin_radius_mm + rolling_resistance_mm) / self.roller_radius_mm
                } else {
                    pin_friction
                }
            }
        }
    }

    /// Friction angle phi = atan(mu_f), in radians.
    pub fn friction_angle_rad(&self) -> f64 {
        self.friction_coefficient().atan()
    }

    /// A copy with another spring rate.
    pub fn with_spring_rate(&self, ks: f64) -> Follower {
        Follower {
            spring_rate_n_per_mm: ks,
            ..*self
        }
    }

    /// A copy with another preload.
    pub fn with_preload(&self, preload_mm: f64) -> Follower {
        Follower {
            preload_mm,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn follower(count: u8, arrangement: SpringArrangement) -> Follower {
        Follower::new(5.0, 3.0)
            .with_count(count)
            .with_arrangement(arrangement)
    }

    #[test]
    fn effective_rate_follows_the_energy_of_each_arrangement() {
        // U = count * ks * Y^2 / 2  or  U = ks * (2Y)^2 / 2; k_eff = d2U/dY2.
        assert_eq!(
            follower(1, SpringArrangement::PerFollower).k_eff_n_per_mm(),
            5.0
        );
        assert_eq!(
            follower(2, SpringArrangement::PerFollower).k_eff_n_per_mm(),
            10.0
        );
        assert_eq!(
            follower(2, SpringArrangement::Shared).k_eff_n_per_mm(),
            20.0
        );
        // The shared spring's tension 2*ks*Y acts on each roller.
        let shared = follower(2, SpringArrangement::Shared);
        assert_eq!(shared.spring_force_per_roller_n(1.0), 2.0 * 5.0 * 1.0);
    }

    #[test]
    fn pin_friction_scales_with_radius_ratio() {
        let f = Follower {
            friction: FrictionSource::Pin {
                pin_friction: 0.2,
                pin_radius_mm: 1.5,
                rolling_resistance_mm: 0.003,
            },
            ..follower(1, SpringArrangement::PerFollower)
        };
        assert!((f.friction_coefficient() - (0.2 * 1.5 + 0.003) / 3.0).abs() < 1e-15);
    }
}

/// A spring a catalogue offers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CatalogueSpring {
    /// Part number.
    pub part: String,
    /// Rate.
    pub rate_n_per_mm: f64,
    /// Free length.
    pub free_length_mm: f64,
    /// Solid length.
    pub solid_length_mm: f64,
    /// Largest working deflection the maker allows.
    pub max_deflection_mm: f64,
    /// Outer diameter.
    pub outer_diameter_mm: f64,
}

/// A spring catalogue named in the spec (`follower.spring_catalogue`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpringCatalogue {
    /// The file it came from.
    pub source: String,
    /// Its springs.
    pub springs: Vec<CatalogueSpring>,
}
