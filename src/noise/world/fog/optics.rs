//! The transmitter/receiver overlap of a biaxial sensor (the HDL-32E's from its optics).

/// Transmitter/receiver overlap xi(r): the fraction of the transmitted beam's cross
/// section that the receiver sees at range r.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Overlap {
    /// Hahner et al.'s ramp: 0 below `start_m` (R1), 1 above `full_m` (R2), linear
    /// between.
    Linear {
        /// R1 in metres (> 0).
        start_m: f64,
        /// R2 in metres (>= R1).
        full_m: f64,
    },
    /// Geometric overlap of a biaxial lidar with parallel axes and circular apertures.
    Biaxial(Biaxial),
}

/// A biaxial transmitter/receiver pair with parallel optical axes (all lengths in
/// metres, angles as full angles in radians): the beam is a uniform disk of radius
/// a_t + r tan(theta_t / 2), the receiver's field a disk of radius a_r + r tan(theta_r / 2),
/// their centres `separation_m` apart (Measures, "Laser Remote Sensing", ch. 7;
/// Stelmaszczyk et al., Appl. Opt. 44, 2005, top-hat beam).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Biaxial {
    /// d: distance between the transmitter's and receiver's optical axes.
    pub separation_m: f64,
    /// a_t: radius of the transmitted beam at the exit aperture.
    pub tx_radius_m: f64,
    /// a_r: radius of the receiver's aperture.
    pub rx_radius_m: f64,
    /// theta_t: full divergence angle of the beam.
    pub divergence_rad: f64,
    /// theta_r: full field-of-view angle of the receiver (one detector).
    pub fov_rad: f64,
}

/// Area of the intersection of two disks of radii `a` and `b` whose centres are `d`
/// apart (the lens-shaped region: two circular segments).
pub fn disk_intersection(d: f64, a: f64, b: f64) -> f64 {
    if d >= a + b {
        return 0.0;
    }
    if d <= (a - b).abs() {
        let m = a.min(b);
        return std::f64::consts::PI * m * m;
    }
    let ca = ((d * d + a * a - b * b) / (2.0 * d * a)).clamp(-1.0, 1.0);
    let cb = ((d * d + b * b - a * a) / (2.0 * d * b)).clamp(-1.0, 1.0);
    let k = ((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b)).max(0.0);
    a * a * ca.acos() + b * b * cb.acos() - 0.5 * k.sqrt()
}

impl Biaxial {
    /// Beam radius w_t(r).
    pub fn beam_radius(&self, r: f64) -> f64 {
        self.tx_radius_m + r * (self.divergence_rad / 2.0).tan()
    }

    /// Receiver field radius w_r(r).
    pub fn field_radius(&self, r: f64) -> f64 {
        self.rx_radius_m + r * (self.fov_rad / 2.0).tan()
    }

    /// R1: the field first touches the beam (w_t + w_r = d); 0 if they overlap at the
    /// sensor already.
    pub fn start_m(&self) -> f64 {
        let gap = self.separation_m - self.tx_radius_m - self.rx_radius_m;
        let grow = (self.divergence_rad / 2.0).tan() + (self.fov_rad / 2.0).tan();
        (gap / grow).max(0.0)
    }

    /// R2: the field contains the whole beam (w_r - w_t >= d); infinite when the
    /// receiver's field never grows around the beam.
    pub fn full_m(&self) -> f64 {
        let need = self.separation_m + self.tx_radius_m - self.rx_radius_m;
        if need <= 0.0 {
            return 0.0;
        }
        let grow = (self.fov_rad / 2.0).tan() - (self.divergence_rad / 2.0).tan();
        if grow <= 0.0 {
            f64::INFINITY
        } else {
            need / grow
        }
    }

    /// xi(r): intersection of beam and field over the beam's area.
    pub fn overlap(&self, r: f64) -> f64 {
        self.overlap_with(
            r,
            (self.divergence_rad / 2.0).tan(),
            (self.fov_rad / 2.0).tan(),
        )
    }

    /// [`Biaxial::overlap`] given tan(theta_t / 2) and tan(theta_r / 2), for callers that
    /// evaluate it per particle.
    pub fn overlap_with(&self, r: f64, tan_beam: f64, tan_field: f64) -> f64 {
        let wt = self.tx_radius_m + r * tan_beam;
        let wr = self.rx_radius_m + r * tan_field;
        let inter = disk_intersection(self.separation_m, wt, wr);
        (inter / (std::f64::consts::PI * wt * wt)).min(1.0)
    }
}

impl Overlap {
    /// xi(r).
    pub fn at(&self, r: f64) -> f64 {
        match *self {
            Overlap::Linear { start_m, full_m } => {
                if r <= start_m {
                    0.0
                } else if r >= full_m {
                    1.0
                } else {
                    (r - start_m) / (full_m - start_m)
                }
            }
            Overlap::Biaxial(b) => b.overlap(r),
        }
    }

    /// R1: xi = 0 below. The biaxial overlap is integrated from 1 cm at least, so that
    /// touching apertures (R1 = 0) leave no 1/r^2 singularity at the sensor.
    pub fn start_m(&self) -> f64 {
        match *self {
            Overlap::Linear { start_m, .. } => start_m,
            Overlap::Biaxial(b) => b.start_m().max(0.01),
        }
    }

    /// R2: xi = 1 from here on (may be infinite).
    pub fn full_m(&self) -> f64 {
        match *self {
            Overlap::Linear { full_m, .. } => full_m,
            Overlap::Biaxial(b) => b.full_m(),
        }
    }
}

/// HDL-32E optics used by the default biaxial overlap (module comment: sources and
/// bounds). Full beam divergence (rad): the manual's spot, about 4 in wide at 100 ft.
pub const HDL32E_DIVERGENCE_MRAD: f64 = 3.3;
/// Receiver field of view (full angle, mrad): not published; 1.25 x the divergence, the
/// low end of the bounds (1.25-3 x), calibrated against a real HDL-32E in fog (module
/// comment).
pub const HDL32E_FOV_MRAD: f64 = 4.1;
/// Transmitter and receiver clear apertures (diameter, mm): not published; the low end
/// of the bounds (20-30 mm), calibrated with the field of view.
pub const HDL32E_APERTURE_MM: f64 = 20.0;
/// Distance between the two optical axes (mm): not published; estimated.
pub const HDL32E_SEPARATION_MM: f64 = 30.0;

/// The biaxial optics of the HDL-32E (the constants above).
pub fn hdl32e_optics() -> Biaxial {
    Biaxial {
        separation_m: HDL32E_SEPARATION_MM * 1e-3,
        tx_radius_m: HDL32E_APERTURE_MM * 0.5e-3,
        rx_radius_m: HDL32E_APERTURE_MM * 0.5e-3,
        divergence_rad: HDL32E_DIVERGENCE_MRAD * 1e-3,
        fov_rad: HDL32E_FOV_MRAD * 1e-3,
    }
}

/// The default overlap: the biaxial geometry of the HDL-32E.
pub fn hdl32e_overlap() -> Overlap {
    Overlap::Biaxial(hdl32e_optics())
}
