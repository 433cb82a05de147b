#!/usr/bin/env bash
# Makes what DDS Security with Cyclone's own plugins needs (docs/security.md, "DDS"), in a folder:
#   identity_ca.pem/.key     the identity CA: signs every participant's certificate
#   permissions_ca.pem/.key  the permissions CA: signs the governance and permissions documents
#   governance.xml/.p7s      the domain's rules: no unauthenticated participant, discovery and
#                            liveliness encrypted, topic data encrypted, read and write access
#                            control on every topic (domains 0..230)
#   NAME.pem/.key            the identity of fusiond and of every sensor NAME
#   permissions_NAME.xml/.p7s  fusiond may subscribe to the points topic, a sensor may publish it
#   dds_NAME.xml             the complete Cyclone configuration of NAME: the loopback settings of
#                            fusiond's embedded one plus the security plugins and these files;
#                            run NAME with CYCLONEDDS_URI=file://DIR/dds_NAME.xml
#   security_NAME.xml        the security part alone, to list after another configuration:
#                            CYCLONEDDS_URI=file:///OTHER.xml,file://DIR/security_NAME.xml
# Usage: scripts/make_dds_security.sh DIR [SENSOR...]   (default sensor: "sensor")
#   FUSION_DDS_TOPIC        the points topic (default fusion/points)
#   FUSION_DDS_SECURITY_LIB the folder of libdds_security_{auth,ac,crypto}.so (default: Debian's
#                           libddsc0debian folder)
# Refuses to overwrite an existing identity CA in DIR.
set -euo pipefail
tool=make_dds_security.sh

usage() { sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; }
if [ $# -ge 1 ] && { [ "$1" = "--help" ] || [ "$1" = "-h" ]; }; then usage; exit 0; fi
if [ $# -lt 1 ] || [ "${1#-}" != "$1" ]; then usage >&2; exit 2; fi
command -v openssl > /dev/null || { echo "$tool: needs openssl (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$1"
dir=$(cd "$1" && pwd)
shift
sensors=("$@")
[ ${#sensors[@]} -gt 0 ] || sensors=(sensor)
topic=${FUSION_DDS_TOPIC:-fusion/points}
case "$dir$topic" in *[\<\>\&\"\',]*)
  echo "$tool: the folder and topic may not contain < > & \" ' or a comma (they go into XML)" >&2
  exit 2 ;;
esac
for name in fusiond "${sensors[@]}"; do
  [[ $name =~ ^[A-Za-z0-9_-]+$ ]] || { echo "$tool: bad identity name '$name' (letters, digits, _ -)" >&2; exit 2; }
done
lib=${FUSION_DDS_SECURITY_LIB:-/usr/lib/$(dpkg-architecture -qDEB_HOST_MULTIARCH 2> /dev/null || echo x86_64-linux-gnu)/libddsc0debian}
for plugin in auth ac crypto; do
  [ -f "$lib/libdds_security_$plugin.so" ] || {
    echo "$tool: no $lib/libdds_security_$plugin.so (Debian: apt-get install libddsc0debian; or set FUSION_DDS_SECURITY_LIB)" >&2
    exit 1
  }
done
if [ -e "$dir/identity_ca.key" ]; then
  echo "$tool: $dir/identity_ca.key exists; remove the folder's files to make new ones" >&2
  exit 1
fi
umask 077
quiet() { "$@" > /dev/null 2>&1 || { echo "$tool: failed: $*" >&2; exit 1; }; }
ec_key() { quiet openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$1"; }

# ---- the two CAs and the identities (ECDSA P-256, which Cyclone's auth plugin accepts) ---------
make_ca() {  # make_ca NAME CN KEY_USAGE
  ec_key "$dir/$1.key"
  quiet openssl req -x509 -key "$dir/$1.key" -days 3650 -subj "/O=fusion/CN=$2" -out "$dir/$1.pem" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,$3"
}
make_ca identity_ca "fusion DDS identity CA" keyCertSign,cRLSign
# The permissions CA signs the documents itself (S/MIME): without digitalSignature the plugin
# refuses them ("unsuitable certificate purpose").
make_ca permissions_ca "fusion DDS permissions CA" digitalSignature,keyCertSign,cRLSign
make_identity() {  # make_identity NAME
  ec_key "$dir/$1.key"
  quiet openssl req -new -key "$dir/$1.key" -subj "/O=fusion/CN=$1" -out "$dir/$1.csr"
  quiet openssl x509 -req -in "$dir/$1.csr" -CA "$dir/identity_ca.pem" -CAkey "$dir/identity_ca.key" \
    -CAcreateserial -days 825 -out "$dir/$1.pem"
  rm -f "$dir/$1.csr"
}
for name in fusiond "${sensors[@]}"; do make_identity "$name"; done
rm -f "$dir/identity_ca.srl"

# ---- governance and permissions, signed (S/MIME) by the permissions CA ---------------------------
smime_sign() {  # smime_sign BASENAME: BASENAME.xml -> BASENAME.p7s
  quiet openssl smime -sign -text -in "$dir/$1.xml" -out "$dir/$1.p7s" \
    -signer "$dir/permissions_ca.pem" -inkey "$dir/permissions_ca.key"
}
domains='<domains><id_range><min>0</min><max>230</max></id_range></domains>'
cat > "$dir/governance.xml" << EOF
<?xml version="1.0" encoding="utf-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="https://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
 <domain_access_rules>
  <domain_rule>
   $domains
   <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
   <enable_join_access_control>true</enable_join_access_control>
   <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
   <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
   <rtps_protection_kind>NONE</rtps_protection_kind>
   <topic_access_rules>
    <topic_rule>
     <topic_expression>*</topic_expression>
     <enable_discovery_protection>true</enable_discovery_protection>
     <enable_liveliness_protection>true</enable_liveliness_protection>
     <enable_read_access_control>true</enable_read_access_control>
     <enable_write_access_control>true</enable_write_access_control>
     <metadata_protection_kind>SIGN</metadata_protection_kind>
     <data_protection_kind>ENCRYPT</data_protection_kind>
    </topic_rule>
   </topic_access_rules>
  </domain_rule>
 </domain_access_rules>
</dds>
EOF
smime_sign governance

not_before=$(date -u -d '-1 day' +%Y-%m-%dT%H:%M:%S)
not_after=$(date -u -d '+825 days' +%Y-%m-%dT%H:%M:%S)
make_permissions() {  # make_permissions NAME publish|subscribe
  # The subject exactly as the plugin compares it: the certificate's, in RFC 2253 form.
  local subject
  subject=$(openssl x509 -noout -subject -nameopt RFC2253 -in "$dir/$1.pem" | sed 's/^subject=//')
  cat > "$dir/permissions_$1.xml" << EOF
<?xml version="1.0" encoding="utf-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="https://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
 <permissions>
  <grant name="$1">
   <subject_name>$subject</subject_name>
   <validity><not_before>$not_before</not_before><not_after>$not_after</not_after></validity>
   <allow_rule>
    $domains
    <$2><topics><topic>$topic</topic></topics></$2>
   </allow_rule>
   <default>DENY</default>
  </grant>
 </permissions>
</dds>
EOF
  smime_sign "permissions_$1"
}
make_permissions fusiond subscribe
for name in "${sensors[@]}"; do make_permissions "$name" publish; done

# ---- Cyclone configurations per identity ---------------------------------------------------------
security_block() {  # security_block NAME: the <Security> element of NAME
  cat << EOF
 <Security>
  <Authentication>
   <Library path="$lib/libdds_security_auth.so" initFunction="init_authentication" finalizeFunction="finalize_authentication"/>
   <IdentityCA>file:$dir/identity_ca.pem</IdentityCA>
   <IdentityCertificate>file:$dir/$1.pem</IdentityCertificate>
   <PrivateKey>file:$dir/$1.key</PrivateKey>
  </Authentication>
  <AccessControl>
   <Library path="$lib/libdds_security_ac.so" initFunction="init_access_control" finalizeFunction="finalize_access_control"/>
   <PermissionsCA>file:$dir/permissions_ca.pem</PermissionsCA>
   <Governance>file:$dir/governance.p7s</Governance>
   <Permissions>file:$dir/permissions_$1.p7s</Permissions>
  </AccessControl>
  <Cryptographic>
   <Library path="$lib/libdds_security_crypto.so" initFunction="init_crypto" finalizeFunction="finalize_crypto"/>
  </Cryptographic>
 </Security>
EOF
}
# The loopback settings are those of kLoopbackDdsConfig (idl/src/participant.cc): keep them equal
# (a test compares them).
make_config() {  # make_config NAME
  {
    cat << EOF
<CycloneDDS xmlns="https://cdds.io/config"><Domain id="any">
 <General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
  <AllowMulticast>false</AllowMulticast>
  <MaxMessageSize>65500B</MaxMessageSize><FragmentSize>65000B</FragmentSize></General>
 <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>
  <Peers><Peer address="127.0.0.1"/></Peers></Discovery>
 <Internal><SocketReceiveBufferSize min="4MB"/>
  <DefragReliableMaxSamples>4</DefragReliableMaxSamples>
  <DefragUnreliableMaxSamples>2</DefragUnreliableMaxSamples></Internal>
EOF
    security_block "$1"
    echo '</Domain></CycloneDDS>'
  } > "$dir/dds_$1.xml"
  # The security alone, to list after another network configuration (Cyclone merges the list).
  {
    echo '<CycloneDDS xmlns="https://cdds.io/config"><Domain id="any">'
    security_block "$1"
    echo '</Domain></CycloneDDS>'
  } > "$dir/security_$1.xml"
}
for name in fusiond "${sensors[@]}"; do make_config "$name"; done
chmod 644 "$dir"/*.pem "$dir"/*.xml "$dir"/*.p7s
echo "made in $dir: identity_ca.pem, permissions_ca.pem, governance.p7s; identities fusiond ${sensors[*]}" \
  "(NAME.pem/.key, permissions_NAME.p7s, dds_NAME.xml: CYCLONEDDS_URI=file://$dir/dds_NAME.xml)"
