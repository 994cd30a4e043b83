#pragma once
/// \file
/// Detection in a scaled copy of the coordinates (internal). The kernels square and cube
/// coordinate differences, so coordinates far beyond 1 overflow and far below underflow. Every
/// detector therefore computes on the positions multiplied by one power of two 2^k, chosen from
/// the frame's largest finite coordinate magnitude M so that M 2^k lies near 1. Multiplying by
/// 2^k changes no bit of a mantissa unless the product leaves the normal range, so the contacts
/// are those of the scaled positions, and the distances, scaled back by 2^-k, are exact; the
/// normals and barycentric coordinates need no change. k = 0 (no copy at all) while M lies in
/// [2^-64, 2^64), where nothing over- or underflows; outside, k is a multiple of 32, so it stays
/// the same from frame to frame while M changes by less than a factor of 2^16.

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>

#include <string_view>

namespace crumple::detail {

/// The largest |coordinate| over the finite coordinates of x (NaN and infinities are left out:
/// the detectors carry them through, scaling keeps them); 0 when there are none. Parallel over
/// `threads` (0 = all) for large x.
Scalar finite_magnitude(PositionsView x, int threads);

/// The exponent k of the scale 2^k the detectors compute in, for a frame whose finite
/// coordinates have largest magnitude M: 0 while M = 0 or M in [2^-64, 2^64); otherwise the
/// multiple of 32 that brings M into [2^-16, 2^16).
int detection_exponent(Scalar magnitude);

/// y = 2^k x, coordinate by coordinate, exactly: throws `InputError` naming `what` (e.g.
/// "positions"), the vertex and the coordinate when a finite coordinate would lose bits, that is
/// when x spans more than the double range (its smallest non-zero magnitudes below 2^-1022 of
/// the largest, about 1e-308). NaN and infinities stay as they are. Parallel like
/// `finite_magnitude`.
void scale_positions(PositionsView x, int k, Positions& y, int threads, std::string_view what);

/// The largest thickness a detector is given: every pair of finite points of a frame scaled to
/// M < 2^64 is closer than it, so a larger one changes no contact and only risks overflow.
inline constexpr Scalar kMaxScaledThickness = 0x1p80;

/// The thickness h in the scaled frame: 2^k h, at most `kMaxScaledThickness`, and positive when
/// h is (a thickness that underflows keeps the contacts at distance 0).
Scalar scaled_thickness(Scalar h, int k);

/// Multiplies every distance of `set` by 2^k (correctly rounded: exact unless it leaves the
/// normal range).
void scale_distances(ContactSet& set, int k);

}  // namespace crumple::detail
