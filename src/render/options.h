#pragma once
// Parsing of the render options the commands share. Each parser throws Error
// naming the flag and the text it could not use.
#include <string>

#include "core/vec.h"
#include "render/reference.h"

namespace edrnr {

// "white", "black" or "R,G,B" with each component in [0, 1].
void parse_background(const std::string& text, const std::string& flag, float rgb[3]);

// "auto", "float" or "quantized".
ModelForm parse_model_form(const std::string& text, const std::string& flag);
const char* model_form_name(ModelForm form);

// "X,Y,Z": three finite numbers.
Vec3f parse_vec3(const std::string& text, const std::string& flag);

}  // namespace edrnr
