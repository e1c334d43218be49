//! One SVG page per flight: roll and pitch (true, estimated, target), the height (true,
//! estimated, the hold's target, where the hold was in force), the four motor compare values,
//! and the supervisor's state with the altitude, on a shared time axis.

use fcu_core::supervisor::FlightState;
use plotters::prelude::*;

use crate::{LogRow, VerticalMode};

/// Where a state is drawn on the state panel, bottom to top: from no flight at all up to the
/// motors under stick control. The match is exhaustive, so every state has its level.
fn state_level(state: FlightState) -> usize {
    match state {
        FlightState::Fault => 0,
        FlightState::Calibrating => 1,
        FlightState::Disarmed => 2,
        FlightState::Arming => 3,
        FlightState::FailsafeOff => 4,
        FlightState::FailsafeLevel => 5,
        FlightState::Armed => 6,
    }
}

/// The state drawn at `level`, if any.
fn state_at_level(level: usize) -> Option<FlightState> {
    FlightState::ALL.into_iter().find(|s| state_level(*s) == level)
}

/// (label, colour, stroke width, which of (true, estimated, target) to draw).
type Series = (&'static str, RGBColor, u32, fn((f64, f64, f64)) -> f64);

/// (label, colour, stroke width, the value of a row).
type HeightSeries = (&'static str, RGBColor, u32, fn(&LogRow) -> f64);

/// At most this many points per series: a 26 s flight at 800 Hz has 20 800 rows, far more
/// than a page can show, and the SVG stays small.
const MAX_POINTS: usize = 2500;

/// The points that have a value: a log recorded from a board has no true attitude, target or
/// altitude (NaN), which would otherwise be drawn along the panel's edge.
fn drawn(points: impl Iterator<Item = (f64, f64)>) -> impl Iterator<Item = (f64, f64)> {
    points.filter(|(_, y)| y.is_finite())
}

const BLUE: RGBColor = RGBColor(31, 119, 180);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);
const RED: RGBColor = RGBColor(214, 39, 40);
const PURPLE: RGBColor = RGBColor(148, 103, 189);

/// One panel of the page.
type Panel<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

/// A plotting error as text (the caller names the file).
fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Write the plot to `path`. `title` goes on top.
pub fn write_svg(rows: &[LogRow], title: &str, path: &std::path::Path) -> Result<(), String> {
    page(rows, title, path).map_err(|e| format!("plotting {}: {e}", path.display()))
}

fn page(rows: &[LogRow], title: &str, path: &std::path::Path) -> Result<(), String> {
    let root = SVGBackend::new(path, (1200, 1620)).into_drawing_area();
    root.fill(&WHITE).map_err(text)?;
    let (top, body) = root.split_vertically(40);
    top.titled(title, ("sans-serif", 22)).map_err(text)?;
    let panels = body.split_evenly((5, 1));
    let [roll, pitch, height, motors, state] = panels.as_slice() else {
        return Err("plot layout".to_string());
    };

    let t_end = rows.last().map_or(1.0, |r| r.t_s).max(0.1);
    let stride = (rows.len() / MAX_POINTS).max(1);
    let rows: Vec<&LogRow> = rows.iter().step_by(stride).collect();

    angle_panel(roll, "roll (° , right side down +)", &rows, t_end, |r| (r.roll_deg, r.est_roll_deg, r.roll_target_deg))?;
    angle_panel(pitch, "pitch (°, nose up +)", &rows, t_end, |r| (r.pitch_deg, r.est_pitch_deg, r.pitch_target_deg))?;
    height_panel(height, &rows, t_end)?;
    motor_panel(motors, &rows, t_end)?;
    state_panel(state, &rows, t_end)?;
    root.present().map_err(text)
}

/// An angle's true, estimated and target values (`get`), on a symmetric axis that fits them.
fn angle_panel(area: &Panel<'_>, name: &str, rows: &[&LogRow], t_end: f64, get: fn(&LogRow) -> (f64, f64, f64)) -> Result<(), String> {
    let lim = rows
        .iter()
        .map(|r| {
            let (a, b, c) = get(r);
            a.abs().max(b.abs()).max(c.abs())
        })
        .fold(5.0f64, f64::max)
        .min(90.0)
        * 1.1;
    let mut ch = ChartBuilder::on(area)
        .caption(name, ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, -lim..lim)
        .map_err(text)?;
    ch.configure_mesh().x_desc("t (s)").y_desc("deg").light_line_style(WHITE.mix(0.0)).draw().map_err(text)?;
    let series: [Series; 3] = [("target", RED, 2, |v| v.2), ("true", BLUE, 2, |v| v.0), ("estimated", ORANGE, 1, |v| v.1)];
    for (label, color, width, pick) in series {
        ch.draw_series(LineSeries::new(drawn(rows.iter().map(|r| (r.t_s, pick(get(r))))), color.stroke_width(width)))
            .map_err(text)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
    }
    ch.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(text)
}

/// The height: true, estimated, the hold's target, and a band along the bottom where the
/// hold (green) or the failsafe's descent (red) sets the thrust.
fn height_panel(area: &Panel<'_>, rows: &[&LogRow], t_end: f64) -> Result<(), String> {
    let top = rows
        .iter()
        .flat_map(|r| [r.alt_m, r.vertical.est_alt_m, r.vertical.alt_target_m])
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::max)
        .min(100.0)
        * 1.15;
    let bottom = -0.1 * top;
    let mut ch = ChartBuilder::on(area)
        .caption("height (m above take-off; band: green hold, red failsafe descent)", ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, bottom..top)
        .map_err(text)?;
    ch.configure_mesh().x_desc("t (s)").y_desc("m").light_line_style(WHITE.mix(0.0)).draw().map_err(text)?;
    let series: [HeightSeries; 3] = [
        ("target", RED, 2, |r| r.vertical.alt_target_m),
        ("true", BLUE, 2, |r| r.alt_m),
        ("estimated", ORANGE, 1, |r| r.vertical.est_alt_m),
    ];
    for (label, color, width, pick) in series {
        // A target is drawn only where there is one: a gap where the hold is off.
        let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for r in rows {
            let v = pick(r);
            match segments.last_mut() {
                Some(seg) if v.is_finite() => seg.push((r.t_s, v)),
                Some(seg) if !seg.is_empty() => segments.push(Vec::new()),
                _ => {}
            }
        }
        let mut first = true;
        for seg in segments.into_iter().filter(|s| !s.is_empty()) {
            let drawn = ch.draw_series(LineSeries::new(seg, color.stroke_width(width))).map_err(text)?;
            if first {
                drawn.label(label).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
                first = false;
            }
        }
    }
    let band = 0.6 * bottom;
    for (mode, color) in [(VerticalMode::Hold, GREEN), (VerticalMode::Descent, RED)] {
        ch.draw_series(rows.iter().filter(|r| r.vertical.mode == Some(mode)).map(|r| Circle::new((r.t_s, band), 1, color.filled())))
            .map_err(text)?;
    }
    ch.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(text)
}

/// The four motors' compare values.
fn motor_panel(area: &Panel<'_>, rows: &[&LogRow], t_end: f64) -> Result<(), String> {
    let mut ch = ChartBuilder::on(area)
        .caption("motor compare values (TIM4 CCR, 0..2000 = 0..100 % duty)", ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, 0.0..2000.0)
        .map_err(text)?;
    ch.configure_mesh().x_desc("t (s)").light_line_style(WHITE.mix(0.0)).draw().map_err(text)?;
    let names = ["M1 rear-right CW", "M2 front-right CCW", "M3 front-left CW", "M4 rear-left CCW"];
    for (m, (label, color)) in names.into_iter().zip([BLUE, ORANGE, GREEN, PURPLE]).enumerate() {
        ch.draw_series(LineSeries::new(
            rows.iter().map(|r| (r.t_s, f64::from(r.motors.get(m).copied().unwrap_or(0)))),
            color.stroke_width(1),
        ))
        .map_err(text)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
    }
    ch.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(text)
}

/// The state's name at a whole level of the state axis, nothing between levels.
fn state_label(v: &f64) -> String {
    let i = v.round();
    if (v - i).abs() < 0.01 && i >= 0.0 {
        state_at_level(i as usize).map_or(String::new(), |s| s.name().to_string())
    } else {
        String::new()
    }
}

/// State and altitude (altitude scaled onto the state axis: 1 level = 0.5 m), and where the
/// transmitter's link was off.
fn state_panel(area: &Panel<'_>, rows: &[&LogRow], t_end: f64) -> Result<(), String> {
    let mut ch = ChartBuilder::on(area)
        .caption("flight state (steps) and altitude (m × 2, dashed)", ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(90)
        .build_cartesian_2d(0.0..t_end, -0.5..(FlightState::ALL.len() as f64 - 0.5))
        .map_err(text)?;
    ch.configure_mesh()
        .x_desc("t (s)")
        .y_labels(FlightState::ALL.len())
        .y_label_formatter(&state_label)
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(text)?;
    ch.draw_series(LineSeries::new(rows.iter().map(|r| (r.t_s, state_level(r.state) as f64)), BLACK.stroke_width(2)))
        .map_err(text)?
        .label("state")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    ch.draw_series(drawn(rows.iter().step_by(4).map(|r| (r.t_s, 2.0 * r.alt_m))).map(|p| Circle::new(p, 1, GREEN.filled())))
        .map_err(text)?
        .label("altitude (m × 2)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREEN.stroke_width(2)));
    // Link lost as seen by the transmitter script: a red band at the bottom.
    ch.draw_series(rows.iter().filter(|r| !r.link_tx).map(|r| Circle::new((r.t_s, -0.35), 2, RED.filled())))
        .map_err(text)?
        .label("radio link off")
        .legend(move |(x, y)| Circle::new((x + 10, y), 3, RED.filled()));
    ch.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `points` of every polyline drawn in `color` (`#RRGGBB`).
    fn polylines(svg: &str, color: &str) -> Vec<usize> {
        svg.split("<polyline ")
            .skip(1)
            .filter_map(|p| p.split_once("/>").map(|(tag, _)| tag))
            .filter(|tag| tag.contains(&format!("stroke=\"{color}\"")))
            .map(|tag| tag.split(" points=\"").nth(1).map_or(0, |p| p.split_whitespace().count()))
            .collect()
    }

    #[test]
    fn the_height_panel_draws_the_target_only_where_the_hold_has_one() {
        // Held 2–4 s and 6–8 s of a 10 s flight: two target segments, the true height whole.
        let rows: Vec<LogRow> = (0..1000)
            .map(|k| {
                let t = f64::from(k) / 100.0;
                let mut r = LogRow::steady(t);
                let held = (2.0..4.0).contains(&t) || (6.0..8.0).contains(&t);
                r.vertical = crate::Vertical {
                    est_alt_m: 1.01,
                    alt_target_m: if held { 1.0 } else { f64::NAN },
                    climb_m_s: 0.0,
                    est_climb_m_s: 0.0,
                    mode: Some(if held { VerticalMode::Hold } else { VerticalMode::Manual }),
                    mode_chosen: None,
                    baro_fault: None,
                };
                r
            })
            .collect();
        let path = std::env::temp_dir().join(format!("fcu-log-height-{}.svg", std::process::id()));
        write_svg(&rows, "height", &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert!(svg.contains("height (m above take-off"));
        // Red: the roll and pitch targets (whole) and the height target's two pieces (the
        // legend's short strokes aside).
        let red: Vec<usize> = polylines(&svg, "#D62728").into_iter().filter(|&n| n > 10).collect();
        assert_eq!(red.len(), 4, "{red:?}");
        assert_eq!(red.iter().filter(|&&n| (199..=201).contains(&n)).count(), 2, "{red:?}");
    }

    #[test]
    fn every_state_has_a_level_of_its_own_on_the_panel() {
        let mut levels: Vec<usize> = FlightState::ALL.iter().map(|s| state_level(*s)).collect();
        levels.sort_unstable();
        assert_eq!(levels, (0..FlightState::ALL.len()).collect::<Vec<_>>());
        for s in FlightState::ALL {
            assert_eq!(state_at_level(state_level(s)), Some(s));
        }
        assert_eq!(state_at_level(FlightState::ALL.len()), None);
    }
}
